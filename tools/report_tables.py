#!/usr/bin/env python3
"""Print the headline figures of pmsc's reports as Markdown tables.

Usage: python3 tools/report_tables.py [--no-header] [--headline] PATH...

Each PATH is a demo's output folder holding report.json (the --out folder of `pmsc demo cornell`,
`pmsc demo volume`, `pmsc demo face`, `pmsc demo learn`, `pmsc demo cross`, `pmsc demo synthetic`)
or a JSON file: a `pmsc replay --report` file, or what `build/bin/pmsc_engine_report` prints
(`build/bin/pmsc_engine_report > engine.json`). The script tells the reports apart by their keys
and prints one row per headline figure: the figure, its value, the command that measures it and
the field of the report it comes from. Rows of all the reports go into one table, so its output can
replace a table of figures as it is.

A missing, unreadable or malformed report, or one without a headline field, is one line on stderr
and exit code 2. Standard library only.
"""

import json
import os
import sys

EXIT_BAD_INPUT = 2


class ReportError(Exception):
    """A report that cannot be read or is not what a pmsc demo or benchmark writes."""


# --- value formats ------------------------------------------------------------------------------


def _num(v, digits=3):
    """A number with `digits` significant digits, thousands separated, no exponent for usual sizes."""
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, int):
        return f"{v:,}"
    if v == 0:
        return "0"
    if abs(v) >= 10 ** digits:
        return f"{round(v):,}"
    return f"{v:.{digits}g}"


FORMATS = {
    "x": lambda v: _num(v) + "x",  # a speedup
    "rate": lambda v: _num(100 * v, 4) + "%",  # a fraction shown in percent
    "rel": lambda v: _num(100 * v) + "%",  # a relative error shown in percent
    "pct_diag": lambda v: _num(v) + "% of the head diagonal",  # already in percent
    "tol": lambda v: _num(v) + " x the tolerance",
    "ratio": lambda v: _num(v, 4),
    "num": lambda v: _num(v, 4),
    "int": lambda v: _num(v),
    "s": lambda v: _num(v) + " s",
    "mb": lambda v: _num(v) + " MB",
    "deg": lambda v: _num(v) + " degrees",
}


# --- reading fields ---------------------------------------------------------------------------


def field(report, path):
    """The value at a dotted path ("summary.hit_rate"), or None when a key is absent."""
    node = report
    for key in path.split("."):
        if not isinstance(node, dict) or key not in node:
            return None
        node = node[key]
    return node


class Rows:
    """Collects a report's rows; a required field that is absent or not a number is an error."""

    def __init__(self, name, report, command):
        self.name, self.report, self.command, self.rows = name, report, command, []

    def add(self, figure, path, fmt, required=False, divide_by=None):
        value = field(self.report, path)
        if value is None:
            if required:
                raise ReportError(f"{self.name}: missing field '{path}'")
            return
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise ReportError(f"{self.name}: field '{path}' is not a number ({json.dumps(value)[:40]})")
        shown = f"`{path}`"
        if divide_by is not None:
            below = field(self.report, divide_by)
            if not isinstance(below, (int, float)) or isinstance(below, bool) or below == 0:
                if required:
                    raise ReportError(f"{self.name}: field '{divide_by}' is missing, not a number or 0")
                return
            value = value / below
            shown = f"`{path}` / `{divide_by}`"
        self.rows.append((figure, FORMATS[fmt](value), self.command, shown, required))


# --- the reports ------------------------------------------------------------------------------


def _quick(report):
    """The size flags a demo ran with: --quick, or --full (the whole experiment at the default size)."""
    if field(report, "quick") is True:
        return " --quick"
    return " --full" if field(report, "full") is True else ""


def _folder(file):
    return os.path.dirname(file) or "."


def cornell(r, rows):
    rows.add("Cornell box: speedup (full gather / PMSC per frame)", "speedup", "x", required=True)
    rows.add("Cornell box: RMS error of PM vs the full gather", "rms_rel_error", "rel", required=True)
    rows.add("Cornell box: RMS error of the soft-cached output", "soft_rms_rel_error", "rel")
    rows.add("Cornell box: hit rate (validation lights)", "hit_rate", "rate", required=True)
    rows.add("Cornell box: full gather vs converged reference", "reference_rms_rel_error_full", "rel")
    rows.add("Cornell box: PM vs converged reference", "reference_rms_rel_error_pm", "rel")
    rows.add("Cornell box: points", "points", "int")
    rows.add("Cornell box: key points", "key_points", "int")
    rows.add("Cornell box: basis vectors", "basis", "int")
    change = "local_fail_through.local_change"
    rows.add("Cornell box, local change: largest error, local fail-through",
             change + ".local.soft_max_error_over_tolerance", "tol")
    rows.add("Cornell box, local change: points gathered in non-hit frames",
             change + ".local.points_evaluated_fraction_non_hit_mean", "rate")
    rows.add("Cornell box, local change: speedup, local fail-through (1 thread)", change + ".speedup_local", "x")
    rows.add("Cornell box: wall time of the demo", "seconds.total", "s")


def volume(r, rows):
    rows.add("Volume: speedup (full calculation / PMSC per frame)", "speedup", "x", required=True)
    rows.add("Volume: RMS error of PM vs the full calculation", "rms_rel_error", "rel", required=True)
    rows.add("Volume: same, lights between training lights", "rms_rel_error_between", "rel")
    rows.add("Volume: same, light path", "rms_rel_error_path", "rel")
    rows.add("Volume: hit rate", "hit_rate", "rate", required=True)
    rows.add("Volume: PM / full calculation distance to the converged reference",
             "reference_ratio_pm_to_full", "ratio", required=True)
    rows.add("Volume: full calculation vs converged reference", "reference_rms_rel_error_full", "rel")
    rows.add("Volume: PM vs converged reference", "reference_rms_rel_error_pm", "rel")
    rows.add("Volume: validation frames' distance from the basis", "projection_rel_error", "rel")
    rows.add("Volume: active voxels", "points", "int")
    rows.add("Volume: key voxels", "key_points", "int")
    rows.add("Volume: basis vectors", "basis", "int")
    rows.add("Volume: peak resident memory", "peak_rss_mb", "mb")
    rows.add("Volume: wall time of the demo", "seconds.total", "s")


def face(r, rows):
    rows.add("Face: speedup (full pose / PMSC, thread CPU)", "speedup", "x", required=True)
    rows.add("Face: validation hit rate (engine)", "hit_rate", "rate", required=True)
    rows.add("Face: PM largest point error, p99.5 over validation frames", "max_error_pct_bbox_p995", "pct_diag",
             required=True)
    rows.add("Face: worst soft-cached frame (every frame)", "soft_max_error_pct_bbox_max", "pct_diag",
             required=True)
    rows.add("Face: novel frames not hit (blend or miss)", "novel_nonhit_rate", "rate", required=True)
    rows.add("Face: key points", "key_points", "int")
    rows.add("Face: basis vectors", "basis", "int")
    for name in ("novel", "mixed"):
        base = "local_fail_through." + name
        rows.add(f"Face, {name} set: points evaluated, local fail-through",
                 base + ".local.points_evaluated_fraction_mean", "rate")
        rows.add(f"Face, {name} set: points evaluated, whole-frame fail-through",
                 base + ".whole_frame.points_evaluated_fraction_mean", "rate")
        rows.add(f"Face, {name} set: worst soft-cached frame, local fail-through",
                 base + ".local.soft_max_error_pct_bbox_max", "pct_diag")
        rows.add(f"Face, {name} set: speedup, local fail-through (1 thread)", base + ".speedup_local", "x")
        rows.add(f"Face, {name} set: speedup, whole-frame fail-through (1 thread)",
                 base + ".speedup_whole_frame", "x")
    rows.add("Face: wall time of the demo", "seconds.total", "s")


def learn(r, rows):
    rows.add("Learn: day-2 hit rate, day-1 model", "day2.day1_model.hit_rate", "rate", required=True)
    rows.add("Learn: day-2 hit rate, learned model", "day2.learned_model.hit_rate", "rate", required=True)
    rows.add("Learn: day-2 hit rate, model retrained from scratch", "day2.scratch_model.hit_rate", "rate",
             required=True)
    rows.add("Learn: day-2 worst soft-cached frame, learned model", "day2.learned_model.soft_max_error_pct_bbox",
             "pct_diag", required=True)
    rows.add("Learn: day-2 frames over the tolerance, learned model",
             "day2.learned_model.frames_over_tolerance", "int")
    rows.add("Learn: validation hit rate, learned model", "validation.learned_model.hit_rate", "rate")
    rows.add("Learn: largest principal angle, learned vs scratch basis",
             "learn_vs_scratch.largest_principal_angle_deg", "deg")
    rows.add("Learn: keys shared with the scratch model", "learn_vs_scratch.keys_shared", "int")
    rows.add("Learn: learn speed over retraining from scratch", "learn_vs_scratch.scratch_train_seconds", "x",
             required=True, divide_by="learn_vs_scratch.learn_seconds")
    rows.add("Learn: wall time of the demo", "seconds.total", "s")


def cross(r, rows):
    rows.add("Cross PM: validation error p50", "validation.error_pct_bbox.p50", "pct_diag", required=True)
    rows.add("Cross PM: validation error p99", "validation.error_pct_bbox.p99", "pct_diag", required=True)
    rows.add("Cross PM: validation error max", "validation.error_pct_bbox.max", "pct_diag")
    rows.add("Cross PM: validation frames inside their bound", "validation.inside_bound_rate", "rate",
             required=True)
    rows.add("Cross PM: stated coverage of the bound", "bound.coverage", "rate")
    rows.add("Cross PM: novel error max", "novel.error_pct_bbox.max", "pct_diag")
    rows.add("Cross PM: novel bound p50", "novel.bound_pct_bbox.p50", "pct_diag")
    rows.add("Cross PM: novel frames inside their bound", "novel.inside_bound_rate", "rate")
    rows.add("Cross PM: speedup over the full rig (thread CPU)", "speed.speedup_cpu", "x", required=True)
    rows.add("Cross PM: speedup over the full rig (wall)", "speed.speedup_wall", "x")
    rows.add("Cross PM: wall time of the demo", "seconds.total", "s")


def replay(r, rows):
    rows.add("Replay: hit rate", "summary.hit_rate", "rate", required=True)
    rows.add("Replay: blend rate", "summary.blend_rate", "rate", required=True)
    rows.add("Replay: miss rate", "summary.miss_rate", "rate", required=True)
    rows.add("Replay: PM largest point error, p50", "summary.pm_max_point_error.p50", "num")
    rows.add("Replay: PM largest point error, max", "summary.pm_max_point_error.max", "num", required=True)
    rows.add("Replay: soft-cached largest point error, p99.5", "summary.soft_max_point_error.p995", "num")
    rows.add("Replay: soft-cached largest point error, max", "summary.soft_max_point_error.max", "num",
             required=True)
    rows.add("Replay: points evaluated (local fail-through)", "summary.points_evaluated_fraction", "rate")
    rows.add("Replay: key points", "summary.key_points", "int")
    rows.add("Replay: basis vectors", "summary.basis", "int")
    rows.add("Replay: eps_min", "summary.eps_min", "num")
    rows.add("Replay: eps_max", "summary.eps_max", "num")


def cross_replay(r, rows):
    rows.add("Cross replay: key RMS, max", "summary.key_rms.max", "num", required=True)
    rows.add("Cross replay: bound, p50", "summary.bound_max_point_error.p50", "num", required=True)
    rows.add("Cross replay: bound, max", "summary.bound_max_point_error.max", "num")
    rows.add("Cross replay: measured target error, max", "summary.target_max_point_error.max", "num")
    rows.add("Cross replay: frames inside their bound", "summary.inside_bound_rate", "rate")
    rows.add("Cross replay: frames whose bound exceeds the tolerance", "summary.frames_bound_over_tolerance", "int")


def engine(r, rows):
    goals = field(r, "goals") if isinstance(field(r, "goals"), dict) else {}
    for key, figure in (("overhead_ratio", "Engine: serial loop / graph at 1 thread (frames/s)"),
                        ("scaling_2_threads", "Engine: 2 threads / 1 thread (frames/s)"),
                        ("miss_cost_ratio", "Engine: missed frame / plain full evaluation (time)"),
                        ("reconstruct_bandwidth_ratio", "Engine: reconstruction / memcpy bandwidth")):
        goal = goals.get(key)
        rows.add(figure + (f", goal {goal}" if goal else ""), key, "ratio", required=True)


# (name, detector, rows, command): the first detector that matches names the report.
KINDS = [
    ("engine benchmark", lambda r: "overhead_ratio" in r and "scaling_2_threads" in r, engine,
     lambda r, p: "`build/bin/pmsc_engine_report`"),
    ("learn demo", lambda r: "learn_vs_scratch" in r, learn,
     lambda r, p: f"`pmsc demo learn --data DIR --out {_folder(p)}{_quick(r)}`"),
    ("cross demo", lambda r: isinstance(r.get("speed"), dict) and "speedup_cpu" in r["speed"], cross,
     lambda r, p: f"`pmsc demo cross --data DIR --out {_folder(p)}{_quick(r)}`"),
    ("face demo", lambda r: "novel_nonhit_rate" in r, face,
     lambda r, p: f"`pmsc demo face --data DIR --out {_folder(p)}{_quick(r)}`"),
    ("volume demo", lambda r: "reference_ratio_pm_to_full" in r or "active_voxels" in r, volume,
     lambda r, p: f"`pmsc demo volume --out {_folder(p)}{_quick(r)}`"),
    ("Cornell box demo", lambda r: "voxel_size_mm" in r or "samples_per_point" in r, cornell,
     lambda r, p: f"`pmsc demo cornell --out {_folder(p)}{_quick(r)}`"),
    ("cross replay report",
     lambda r: isinstance(r.get("summary"), dict) and r["summary"].get("cross") is True, cross_replay,
     lambda r, p: f"`pmsc replay --report {p}` (a cross model)"),
    ("replay report", lambda r: isinstance(r.get("summary"), dict) and "hit_rate" in r["summary"], replay,
     lambda r, p: f"`pmsc replay --report {p}` or `pmsc demo synthetic --out {_folder(p)}`"),
]


def load(path):
    """The report at `path` (a folder holding report.json, or a JSON file) as a dict."""
    file = os.path.join(path, "report.json") if os.path.isdir(path) else path
    try:
        with open(file, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        raise ReportError(f"{file}: no such file (give a demo's --out folder or a report's JSON file)")
    except (OSError, UnicodeDecodeError) as e:
        raise ReportError(f"{file}: cannot read: {getattr(e, 'strerror', None) or e}")
    try:
        report = json.loads(text)
    except json.JSONDecodeError as e:
        raise ReportError(f"{file}: not valid JSON: {e.msg} at line {e.lineno}, column {e.colno}")
    if not isinstance(report, dict):
        raise ReportError(f"{file}: not a report (the top level is not a JSON object)")
    return file, report


def rows_of(path):
    file, report = load(path)
    for name, matches, collect, command in KINDS:
        if matches(report):
            rows = Rows(file, report, command(report, file))
            collect(report, rows)
            return rows.rows
    keys = ", ".join(sorted(report)[:8])
    raise ReportError(f"{file}: not a report a pmsc demo or benchmark writes (top-level keys: {keys})")


def main(argv):
    args = list(argv)
    header, headline = True, False
    while args and args[0] in ("--no-header", "--headline"):
        header = header and args[0] != "--no-header"
        headline = headline or args[0] == "--headline"
        args = args[1:]
    if not args or any(a in ("-h", "--help") for a in args):
        stream = sys.stdout if args else sys.stderr
        print("usage: python3 tools/report_tables.py [--no-header] [--headline] DIR|REPORT.json...\n"
              "Prints the figures of pmsc demo and benchmark reports as one Markdown table;\n"
              "--headline: only each report's headline figures (the fields it must have).",
              file=stream)
        return 0 if args else EXIT_BAD_INPUT
    try:
        rows = [row for path in args for row in rows_of(path)]
    except ReportError as e:
        print(f"report_tables.py: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if header:
        print("| figure | value | command | report field |")
        print("|---|---|---|---|")
    for figure, value, command, path, required in rows:
        if required or not headline:
            print(f"| {figure} | {value} | {command} | {path} |")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
