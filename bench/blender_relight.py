#!/usr/bin/env python3
"""A scene relit by Blender's Cycles through pmsc: training frames, a model, a light path training
never saw, against Cycles computing every point.

    /usr/bin/python3 bench/blender_relight.py --bin build/bin --share share/blender --work /tmp/bc \\
        [--blend SCENE.blend] [--points 10000] [--grid 12] [--path 30] [--samples 64] [--tolerance-share 0.1]
        [--light direct,indirect|indirect] [--export-threads 1] [--train OPTIONS] [--check]

Steps (each a command a lighting TD would type; docs/blender.md):
  1. the scene: without --blend, `blender -b --python cornell_box.py` builds the measured Cornell
     box as a .blend, a point light on a grid x grid lattice below the ceiling (frames 1 .. grid^2,
     the training frames), then along a path of --path frames over and below it; with --blend,
     `blender -b SCENE.blend --python animate_light.py` keys a new point light on a lattice over the
     scene's meshes and a path across it the same way (its other lights stay);
  2. `pmsc-blender scene.blend sample` draws --points points on its surfaces;
  3. `pmsc export-frames exec:pmsc-blender ...` bakes every point of the training frames and, as the
     reference, of the path frames (one thread: the child's own time per call is logged);
  4. `pmsc train --tolerance T` (T = --tolerance-share of the training frames' largest point value,
     as `pmsc demo cornell` sets it, and the --train options);
  5. `pmsc run` over the path frames, Cycles computing the keys (and what misses) in one Blender.
Renders the first path frame with Blender (full | pmsc | 10 x difference: the values at the points,
path000.png, and the scene's meshes lit by them, path000-lit.png, pmsc's light read back from the
frame's cache as `pmsc run --format vdb` writes it) and prints
the speedup (Cycles' time for every point of a path frame over pmsc's per path frame,
both measured inside the same child, one thread, same samples; and the same over the commands'
wall times, Blender's start and pmsc's own work included), the RMS error against the full
result, the hit rate, the frames over T, and the key call's time (a frame's first call: its keys and
sentinels) split into Blender's fixed cost (the same call at 1 sample) and the samples, and the noise of Cycles' full result (the
path frames baked again with another seed). --check exits 1 when the soft-cached path's RMS error
against the full result is over --check-rms (the tests' gate: the noise makes a largest point error
no gate; docs/blender.md).

Exit codes: 0 done, 1 --check failed, 2 bad arguments or a failed command (one line), 77 Blender
missing and CI not set (a skip; under CI it is exit 2).
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import time

from suite_common import under_ci


PROG = os.path.splitext(os.path.basename(sys.argv[0]))[0]  # this bench, or blender_rig.py importing it


def fail(message):
    print(PROG + ": " + message, file=sys.stderr)
    sys.exit(2)


def run(cmd, env=None):
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    if done.returncode != 0:
        fail("'" + " ".join(cmd)[:300] + "' exited " + str(done.returncode) + ": " + done.stdout.strip()[-600:])
    return done.stdout


def timings(path):
    """(frame, points, seconds) of every call the child logged."""
    rows = []
    if os.path.exists(path):
        with open(path) as f:
            for line in f:
                frame, count, seconds = line.split()
                rows.append((int(frame), int(count), float(seconds)))
    return rows


def first_calls(calls):
    """The first call the child logged for each frame: its key call (the keys, and with them the
    sentinels when the engine asks for both at once: an exec child's calls pay a set-up)."""
    seen, out = set(), []
    for call in calls:
        if call[0] not in seen:
            seen.add(call[0])
            out.append(call)
    return out


def numpy_and_blender():
    """numpy and the path of Blender; without Blender a skip (exit 77), except under CI (exit 2)."""
    try:
        import numpy
    except ImportError:
        fail("needs numpy (run it with the system python3)")
    blender = shutil.which("blender")
    if blender is None:
        if not under_ci():
            print(PROG + ": no blender on PATH: skipped (apt-get install blender)", file=sys.stderr)
            sys.exit(77)
        fail("no blender on PATH (apt-get install blender)")
    return numpy, blender


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--bin", default="build/bin", help="folder of pmsc")
    p.add_argument("--share", default="share/blender", help="folder of pmsc-blender and its scripts")
    p.add_argument("--work", required=True, help="folder for the scene, frames, model and outputs")
    p.add_argument("--blend", default="", help="a .blend to relight (default: the Cornell box, built)")
    p.add_argument("--points", type=int, default=10000)
    p.add_argument("--grid", type=int, default=12)
    p.add_argument("--path", type=int, default=30)
    p.add_argument("--samples", type=int, default=64)
    p.add_argument("--tolerance-share", type=float, default=0.1)
    p.add_argument("--light", default="direct,indirect",
                   help="the passes Cycles bakes (pmsc-blender's --light): direct,indirect (default) or indirect, "
                        "the light the paper's section 8 caches while the renderer traces the direct light itself")
    p.add_argument("--export-threads", type=int, default=1,
                   help="Blenders baking the frames nothing times (the training frames, the path at another seed); "
                        "the path's full frames and pmsc run stay on one thread")
    p.add_argument("--train", default="", help="more `pmsc train` options, as one string (e.g. '--basis 32')")
    p.add_argument("--no-positions", action="store_true",
                   help="train without the points' positions (--positions points.npy, as docs/blender.md trains): "
                        "the sentinels are then drawn in point order, and there are no regions or key neighbours")
    p.add_argument("--reuse", action="store_true",
                   help="keep the scene, points and training frames of --work when they are there (timing again)")
    p.add_argument("--check", action="store_true", help="exit 1 when the RMS error is over --check-rms")
    p.add_argument("--check-rms", type=float, default=0.05, help="the largest RMS error --check accepts")
    args = p.parse_args()
    np, blender = numpy_and_blender()
    if (args.points < 100 or args.grid < 2 or args.path < 1 or args.samples < 1 or not args.tolerance_share > 0
            or args.export_threads < 1):
        fail("--points >= 100, --grid >= 2, --path >= 1, --samples >= 1, --tolerance-share > 0 and --export-threads >= 1")
    os.makedirs(args.work, exist_ok=True)
    w = lambda name: os.path.join(args.work, name)
    pmsc = os.path.join(args.bin, "pmsc")
    launcher = os.path.abspath(os.path.join(args.share, "pmsc-blender"))

    if args.blend and not os.path.isfile(args.blend):
        fail("--blend " + args.blend + ": no such file")
    scene = w("scene.blend")
    reuse = args.reuse and all(os.path.exists(w(f)) for f in ("scene.blend", "points.npy", "train.npy"))
    if not reuse:
        if args.blend:
            run([blender, "-b", os.path.abspath(args.blend), "--python-exit-code", "2", "--python",
                 os.path.join(args.share, "animate_light.py"), "--", "--out", scene, "--grid", str(args.grid),
                 "--path", str(args.path)])
        else:
            run([blender, "-b", "--factory-startup", "--python-exit-code", "2", "--python",
                 os.path.join(args.share, "cornell_box.py"), "--", "--out", scene, "--grid", str(args.grid),
                 "--path", str(args.path)])
        run([launcher, scene, "sample", "--out", w("points.npy"), "--count", str(args.points)])
    frames = args.grid * args.grid + args.path
    train_span, path_span = "0-%d" % (args.grid * args.grid - 1), "%d-%d" % (args.grid * args.grid, frames - 1)

    def evaluator(samples, log, seed=0):
        return ("exec:PMSC_BLENDER_TIMING=%s %s %s serve --points %s --frames 1-%d --samples %d --seed %d --light %s"
                % (log, launcher, scene, w("points.npy"), frames, samples, seed, args.light))

    for name in ("full", "seed", "run", "fixed") if reuse else ("train", "full", "seed", "run", "fixed"):
        if os.path.exists(w(name + ".log")):
            os.remove(w(name + ".log"))
    if not reuse:
        run([pmsc, "export-frames", evaluator(args.samples, w("train.log")), "--out", w("train.npy"), "--frames",
             train_span, "--threads", str(args.export_threads), "--quiet"])
    began = time.perf_counter()
    run([pmsc, "export-frames", evaluator(args.samples, w("full.log")), "--out", w("full.npy"), "--frames",
         path_span, "--threads", "1", "--quiet"])
    full_wall = time.perf_counter() - began
    # The noise of Cycles' full result: the path frames again with another seed.
    run([pmsc, "export-frames", evaluator(args.samples, w("seed.log"), 1), "--out", w("full-seed1.npy"), "--frames",
         path_span, "--threads", str(args.export_threads), "--quiet"])
    train = np.load(w("train.npy"))
    tolerance = args.tolerance_share * float(np.sqrt((train ** 2).sum(axis=2)).max())
    positions = [] if args.no_positions else ["--positions", w("points.npy")]
    out = run([pmsc, "train", "--frames", w("train.npy"), "--out", w("model.pmsc"), "--tolerance", "%.6g" % tolerance]
              + positions + args.train.split())
    shutil.rmtree(w("run"), ignore_errors=True)
    began = time.perf_counter()
    run([pmsc, "run", "--model", w("model.pmsc"), "--evaluator", evaluator(args.samples, w("run.log")), "--frames",
         path_span, "--out", w("run"), "--threads", "1", "--quiet"])
    wall = time.perf_counter() - began
    # Blender's fixed cost of a key call: the same calls at 1 sample.
    shutil.rmtree(w("fixed"), ignore_errors=True)
    run([pmsc, "run", "--model", w("model.pmsc"), "--evaluator", evaluator(1, w("fixed.log")), "--frames",
         path_span, "--out", w("fixed"), "--threads", "1", "--quiet"])

    full = np.load(w("full.npy"))
    first = args.grid * args.grid
    got = np.stack([np.load(os.path.join(w("run"), "frame.%06d.npy" % (first + i)))[0] for i in range(args.path)])
    with open(os.path.join(w("run"), "pmsc-run.%s.json" % path_span)) as f:
        stats = json.load(f)
    point_error = np.sqrt(((got - full) ** 2).sum(axis=2))
    rms = float(np.sqrt(((got - full) ** 2).sum() / (full ** 2).sum()))
    keys = len(json.loads(run([pmsc, "inspect", w("model.pmsc"), "--json"]))["key_indices"])
    full_calls = timings(w("full.log"))
    run_calls = timings(w("run.log"))
    key_calls = first_calls(run_calls)
    fixed_calls = first_calls(timings(w("fixed.log")))
    full_per_frame = sum(t[2] for t in full_calls) / len(full_calls)
    pmsc_per_frame = sum(t[2] for t in run_calls) / args.path
    key_call = sum(t[2] for t in key_calls) / max(1, len(key_calls))
    fixed = sum(t[2] for t in fixed_calls) / max(1, len(fixed_calls))
    over = int((point_error.max(axis=1) > tolerance).sum())
    other = np.load(w("full-seed1.npy"))
    # One draw's noise: two independent draws differ by sqrt(2) times it.
    noise_rms = float(np.sqrt(((other - full) ** 2).sum() / (2 * (full ** 2).sum())))
    noise_point = np.sqrt(((other - full) ** 2).sum(axis=2) / 2)
    report = {
        "scene": os.path.abspath(args.blend) if args.blend else "cornell box",
        "points": args.points, "keys": keys, "training_frames": args.grid * args.grid, "path_frames": args.path,
        "samples": args.samples, "light": args.light, "tolerance": tolerance,
        "hit_rate": stats["hit_rate"], "hits": stats["hits"], "blends": stats["blends"], "misses": stats["misses"],
        "rms_rel_error": rms,
        "noise_rms_rel": noise_rms,
        "noise_largest_point_over_tolerance": float(noise_point.max() / tolerance),
        "frames_over_tolerance": over,
        "largest_point_error_over_tolerance": float(point_error.max() / tolerance),
        "cycles_seconds_per_frame": full_per_frame,
        "pmsc_seconds_per_frame": pmsc_per_frame,
        "speedup": full_per_frame / pmsc_per_frame,
        "key_call_points": sum(t[1] for t in key_calls) / max(1, len(key_calls)),
        "key_call_seconds": key_call,
        "key_call_fixed_seconds": fixed,
        "key_call_samples_seconds": key_call - fixed,
        "speedup_wall": full_wall / wall,
        "cycles_export_wall_seconds": full_wall,
        "pmsc_run_wall_seconds": wall,
        "train_summary": [l for l in out.splitlines() if l.strip().startswith(("basis", "key points", "eps"))],
    }
    # The first path frame as Blender renders the values: full | pmsc | 10 x difference.
    run([blender, "-b", scene, "--python-exit-code", "2", "--python",
         os.path.join(args.share, "show_values.py"), "--", "--points", w("points.npy"), "--full", w("full.npy"),
         "--pmsc", os.path.join(w("run"), "frame.%06d.npy" % first), "--index", "0", "--out", w("path000.png")])
    report["picture"] = w("path000.png")
    # The same frame as the scene renders lit by the values: its meshes lit by Cycles' full result |
    # by pmsc's | 10 x the difference (show_values.py --surfaces). pmsc's light comes as the farm
    # loop hands it to a renderer: the frame's cache written by `pmsc run --format vdb`, read back
    # in Blender.
    shutil.rmtree(w("run-vdb"), ignore_errors=True)
    run([pmsc, "run", "--model", w("model.pmsc"), "--evaluator", evaluator(args.samples, w("vdb.log")), "--frames",
         str(first), "--out", w("run-vdb"), "--threads", "1", "--format", "vdb", "--quiet"])
    report["cache_vdb"] = os.path.join(w("run-vdb"), "frame.%06d.vdb" % first)
    run([blender, "-b", scene, "--python-exit-code", "2", "--python",
         os.path.join(args.share, "show_values.py"), "--", "--points", w("points.npy"), "--full", w("full.npy"),
         "--pmsc", report["cache_vdb"], "--index", "0", "--surfaces",
         "--frame", str(first + 1), "--out", w("path000-lit.png")])
    report["picture_lit"] = w("path000-lit.png")
    with open(w("report.json"), "w") as f:
        json.dump(report, f, indent=2)
    print(json.dumps(report, indent=2))
    if args.check and rms > args.check_rms:
        print("blender_relight: RMS error %.4f against Cycles' full result, over --check-rms %.4f"
              % (rms, args.check_rms), file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
