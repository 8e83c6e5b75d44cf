#!/usr/bin/env python3
"""`pmsc learn` on a take whose second half moves what its first half left still, against
retraining from scratch on both halves.

Each split is four ICT controls and a seed: the first half is frames 0-299 of take SEED with the
four held at 0 (`pmsc_ict_frames --without`), the second half frames 300-599 of the same take with
them free; the test take is 200 frames of seed SEED + 1, every control free. `pmsc train
--tolerance T` (1% of the head diagonal) on the first half, `pmsc learn` with the second, and
`pmsc train` on both halves, each with its defaults; both models replayed on the test take. The
table gives M, the p99.5 over frames of PM's largest point error and of the soft-cached error
(learned / scratch), hits, frames over T, and the wall times of `pmsc learn` and of the scratch
`pmsc train` (one run each). With --novel, a second table: takes whose halves leave controls Y still
that the test take moves, through the learned model with its regions, learned with --no-regions, and
retrained (points evaluated, local frames, frames over T). docs/results/learning.md has the figures.

    /usr/bin/python3 bench/learn_novelty.py --data ICT-FaceKit/FaceXModel --bin build/bin \\
        --work /tmp/learn-novelty

Needs numpy (the system python3). Exits 2 with one line on bad arguments or a failed command, 77
when the face folder is missing and CI is not set (a skip; under CI it is exit 2), and 1 when any
replayed frame comes back over T.
"""
import argparse
import json
import os
import sys
import time

from suite_common import add_clean_argument, discard, fail, require_folder, run

SPLITS = [
    (1, "mouthPucker,cheekPuff_L,jawLeft,eyeWide_R"),
    (9, "mouthSmile_L,browDown_R,mouthShrugUpper,jawRight"),
]

# --novel: (seed, X, Y). The first half holds X and Y at 0, the second half Y only, the test take
# moves everything: Y is novel to the learned and the retrained model alike, so their frames miss
# and the regions' local fail-through shows.
NOVEL = [
    (21, "mouthPucker,cheekPuff_L,jawLeft,eyeWide_R", "jawForward,mouthLeft,cheekPuff_R,browInnerUp_L"),
    (31, "mouthSmile_L,browDown_R,mouthShrugUpper,jawRight", "mouthRight,eyeSquint_L,mouthFunnel,noseSneer_R"),
]


def ict(args, out, frames, seed, without=None):
    if not os.path.exists(out):
        cmd = [os.path.join(args.bin, "pmsc_ict_frames"), "--data", args.data, "--out", out, "--frames",
               str(frames), "--seed", str(seed), "--dtype", "float32"]
        run(cmd + (["--without", without] if without else []))
    return out


def timed(cmd):
    start = time.monotonic()
    run(cmd)
    return time.monotonic() - start


def replay(args, model, take, tolerance):
    report = model + ".json"
    run([os.path.join(args.bin, "pmsc"), "replay", "--model", model, "--frames", take, "--report", report,
         "--quiet"])
    with open(report) as f:
        r = json.load(f)
    s = r["summary"]
    return {"pm": s["pm_max_point_error"]["p995"], "soft": s["soft_max_point_error"]["p995"],
            "worst": max(f["soft_max_point_error"] for f in r["frames"]) / tolerance,
            "local": s.get("local_frames", 0),
            "hit": s["hit_rate"], "M": s["basis"], "evaluated": s["points_evaluated_fraction"],
            "regions": s.get("regions", 0),
            "over": sum(1 for f in r["frames"] if f["soft_max_point_error"] > tolerance)}


def halves(args, np, w, seed, first_without, second_without):
    """first.npy: frames 0-299 of take SEED without `first_without`; second.npy: frames 300-599 of it
    without `second_without` (None: every control free); union.npy both; the test take's path."""
    if not os.path.exists(w("union.npy")):
        first = np.load(ict(args, w("a.npy"), 600, seed, first_without), mmap_mode="r")
        second = np.load(ict(args, w("b.npy"), 600, seed, second_without), mmap_mode="r")
        np.save(w("first.npy"), first[:300])
        np.save(w("second.npy"), second[300:])
        np.save(w("union.npy"), np.concatenate([first[:300], second[300:]]))
        del first, second
        discard(args, [w("a.npy"), w("b.npy")])
    return ict(args, w("test.npy"), 200, seed + 1)


def measure(args, np, seed, controls, tolerance):
    w = lambda name: os.path.join(args.work, "s%d-%s" % (seed, name))
    test = halves(args, np, w, seed, controls, None)
    pmsc = os.path.join(args.bin, "pmsc")
    t = ["--tolerance", "%.6g" % tolerance, "--quiet"]
    run([pmsc, "train", "--frames", w("first.npy"), "--out", w("day1.pmsc")] + t)
    learn_s = timed([pmsc, "learn", "--model", w("day1.pmsc"), "--frames", w("second.npy"), "--out",
                     w("learned.pmsc"), "--quiet"])
    scratch_s = timed([pmsc, "train", "--frames", w("union.npy"), "--out", w("scratch.pmsc")] + t)
    result = (replay(args, w("learned.pmsc"), test, tolerance), replay(args, w("scratch.pmsc"), test, tolerance),
              learn_s, scratch_s)
    discard(args, [w(name) for name in ("test.npy", "first.npy", "second.npy", "union.npy", "day1.pmsc",
                                         "learned.pmsc", "scratch.pmsc")])
    return result


def measure_novel(args, np, seed, x, y, tolerance):
    """Learned (with its regions), learned --no-regions and retrained, replayed on a take that moves Y."""
    w = lambda name: os.path.join(args.work, "n%d-%s" % (seed, name))
    test = halves(args, np, w, seed, x + "," + y, y)
    pmsc = os.path.join(args.bin, "pmsc")
    t = ["--tolerance", "%.6g" % tolerance, "--quiet"]
    run([pmsc, "train", "--frames", w("first.npy"), "--out", w("day1.pmsc")] + t)
    learn = [pmsc, "learn", "--model", w("day1.pmsc"), "--frames", w("second.npy"), "--quiet", "--out"]
    run(learn + [w("learned.pmsc")])
    run(learn + [w("dropped.pmsc"), "--no-regions"])
    run([pmsc, "train", "--frames", w("union.npy"), "--out", w("scratch.pmsc")] + t)
    rows = [(name, replay(args, w(model), test, tolerance)) for name, model in
            (("learned", "learned.pmsc"), ("learned, --no-regions", "dropped.pmsc"), ("retrained", "scratch.pmsc"))]
    discard(args, [w(name) for name in ("test.npy", "first.npy", "second.npy", "union.npy",
                                         "day1.pmsc", "learned.pmsc", "dropped.pmsc", "scratch.pmsc")])
    return rows


def novel_table(args, np, tolerance):
    print("\n| seed / X / Y | model | regions | hits | local frames | points evaluated | frames over T (worst) |")
    print("|---|---|---|---|---|---|---|")
    any_over = False
    for seed, x, y in NOVEL:
        for i, (name, r) in enumerate(measure_novel(args, np, seed, x, y, tolerance)):
            any_over = any_over or r["over"] > 0
            head = "%d / %s / %s" % (seed, x.replace(",", ", "), y.replace(",", ", ")) if i == 0 else ""
            print("| %s | %s | %d | %.1f%% | %d | %.1f%% | %d (%.3f T) |" % (
                head, name, r["regions"], 100 * r["hit"], r["local"], 100 * r["evaluated"], r["over"], r["worst"]),
                flush=True)
    return any_over


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", required=True, help="ICT-FaceKit's FaceXModel folder")
    p.add_argument("--bin", default="build/bin", help="folder of pmsc and pmsc_ict_frames")
    p.add_argument("--work", required=True, help="folder for frames, models and reports (reused)")
    p.add_argument("--tolerance-percent", type=float, default=1.0, help="T in %% of the head diagonal")
    p.add_argument("--novel", action="store_true",
                   help="also the takes that move controls neither half moved: learned with and without "
                        "its regions against retraining (3 more minutes)")
    add_clean_argument(p)
    args = p.parse_args()
    try:
        import numpy as np
    except ImportError:
        fail("needs numpy (run it with the system python3)")
    require_folder(args.data)
    os.makedirs(args.work, exist_ok=True)
    out = run([os.path.join(args.bin, "pmsc_ict_frames"), "--data", args.data, "--out",
               os.path.join(args.work, "part.npy"), "--frames", "1", "--seed", "0"])
    tolerance = args.tolerance_percent / 100 * float(out.split("head bounding-box diagonal ")[1].split()[0])
    print("| split | M learned / scratch | PM p99.5 learned / scratch (ratio) | soft-cached p99.5 (ratio) | "
          "hits learned / scratch | points evaluated learned / scratch (regions) | over T | learn / scratch time |")
    print("|---|---|---|---|---|---|---|---|")
    any_over = False
    for seed, controls in SPLITS:
        l, s, learn_s, scratch_s = measure(args, np, seed, controls, tolerance)
        any_over = any_over or l["over"] > 0 or s["over"] > 0
        print("| seed %d, %s | %d / %d | %.4f / %.4f (%.2fx) | %.4f / %.4f (%.2fx) | %.1f%% / %.1f%% | "
              "%.1f%% / %.1f%% (%d / %d) | %d / %d | %.1f s / %.1f s |"
              % (seed, controls.replace(",", ", "), l["M"], s["M"], l["pm"], s["pm"], l["pm"] / s["pm"], l["soft"],
                 s["soft"], l["soft"] / s["soft"], 100 * l["hit"], 100 * s["hit"], 100 * l["evaluated"],
                 100 * s["evaluated"], l["regions"], s["regions"], l["over"], s["over"], learn_s, scratch_s),
              flush=True)
    if args.novel:
        any_over = novel_table(args, np, tolerance) or any_over
    return 1 if any_over else 0


if __name__ == "__main__":
    sys.exit(main())
