#!/usr/bin/env python3
"""A character posed by Blender's own rig through pmsc: trained on a range of motion, replayed on
real motion-capture takes, against Blender evaluating every vertex.

    /usr/bin/python3 bench/blender_rig.py --bin build/bin --share share/blender --work /tmp/rig \\
        [--bvh TAKE.bvh,...] [--stride 4] [--tolerance-share 0.01] [--train OPTIONS] [--check]

Steps (each a command a rigger or a TD would type; docs/blender.md):
  0. `tools/bvh_range_of_motion.py` writes the range of motion a rigger records for the takes'
     skeleton (every rotation channel swept alone, then poses of all at once), never the takes;
  1. `blender -b --python bvh_character.py` builds the character: the skeleton, a body skinned to
     it, Armature + Corrective Smooth + Subdivision Surface, an action per take (default Debian's
     assimp-testmodels CMU clips 01_01 and 01_03, one subject) and the range of motion's;
  2. `pmsc export-frames exec:pmsc-blender character.blend pose --action rom ... --positions` evaluates every
     frame of the range of motion (every vertex, in the root bone's space), and, as the reference,
     every --stride-th frame of each take;
  3. `pmsc train --tolerance T --positions` the points at the rest pose (the child's positions,
     written by step 2's `pmsc export-frames --positions`) (T = --tolerance-share of the body's size: the median of the training
     frames' bounding-box diagonals) and the --train options;
  4. `pmsc run` over each take, Blender evaluating the keys, the sentinels and what misses.
Prints, per take, the speedup (Blender's time to evaluate every vertex of a replay frame over the child's time
per pmsc frame, both measured inside the same Blender, one thread; and the same over the commands'
wall times, pmsc's reconstruction and Blender's start included), the p99.5 and largest point error
(as a share of the body's size and of T), the hit rate and the frames over T. --check exits 1 when a
frame is over T or the p99.5 point error is over --check-p995 of the body's size.

Exit codes: 0 done, 1 --check failed, 2 bad arguments or a failed command (one line), 77 Blender
missing and CI not set (a skip; under CI it is exit 2).
"""
import argparse
import glob
import json
import os
import shutil
import sys
import time

from blender_relight import fail, first_calls, numpy_and_blender, run, timings  # beside this script

ASSIMP_BVH = "/usr/share/assimp/models/BVH"


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--bin", default="build/bin", help="folder of pmsc")
    p.add_argument("--share", default="share/blender", help="folder of pmsc-blender and its scripts")
    p.add_argument("--work", required=True, help="folder for the character, frames, model and outputs")
    p.add_argument("--bvh", default=f"{ASSIMP_BVH}/01_01.bvh,{ASSIMP_BVH}/01_03.bvh",
                   help="the takes to replay (one skeleton), comma-separated")
    p.add_argument("--stride", type=int, default=4, help="every stride-th frame of each take")
    p.add_argument("--rom", default="", help="more tools/bvh_range_of_motion.py options, as one string")
    p.add_argument("--tolerance-share", type=float, default=0.01)
    p.add_argument("--character", default="", help="more bvh_character.py options, as one string")
    p.add_argument("--train", default="", help="more `pmsc train` options, as one string")
    p.add_argument("--no-positions", action="store_true",
                   help="train without the rest pose's positions (no regions or key neighbours; the sentinels "
                        "spread over the training frame nearest the mean)")
    p.add_argument("--check", action="store_true")
    p.add_argument("--check-p995", type=float, default=0.005, help="the largest p99.5 point error --check accepts")
    args = p.parse_args()
    np, blender = numpy_and_blender()
    takes = args.bvh.split(",")
    if args.stride < 1 or not args.tolerance_share > 0:
        fail("--stride >= 1 and --tolerance-share > 0")
    for take in takes:
        if not os.path.isfile(take):
            fail(f"{take}: no such file (apt-get install assimp-testmodels)")
    os.makedirs(args.work, exist_ok=True)
    w = lambda name: os.path.join(args.work, name)
    pmsc = os.path.join(args.bin, "pmsc")
    launcher = os.path.abspath(os.path.join(args.share, "pmsc-blender"))
    tools = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools")
    run([sys.executable, os.path.join(tools, "bvh_range_of_motion.py"), takes[0], w("rom.bvh")] + args.rom.split())
    character = w("character.blend")
    built = run([blender, "-b", "--factory-startup", "--python-exit-code", "2", "--python",
                 os.path.join(args.share, "bvh_character.py"), "--", "--bvh", ",".join([w("rom.bvh")] + takes),
                 "--out", character] + args.character.split())
    names = ["rom"] + [os.path.splitext(os.path.basename(t))[0] for t in takes]
    lengths = {}
    for line in built.splitlines():
        if line.startswith("bvh_character.py: wrote"):
            print(line)
            for name in names:
                lengths[name] = int(line.split(f"{name} (")[1].split(" frames")[0])

    def evaluator(take, log):
        return (f"exec:PMSC_BLENDER_TIMING={log} {launcher} {character} pose --object Body --action {take} "
                f"--frames 1-{lengths[take]}")

    for log in glob.glob(w("*.log")):
        os.remove(log)
    # The frames, and where the points are (the rest pose, the child's positions answer).
    positions = [] if args.no_positions else ["--positions", w("rest.npy")]
    run([pmsc, "export-frames", evaluator("rom", w("train.log")), "--out", w("train.npy"), "--frames",
         f"0-{lengths['rom'] - 1}", "--threads", "1", "--quiet"] + positions)
    train = np.load(w("train.npy"))
    size = float(np.median(np.linalg.norm(train.max(axis=1) - train.min(axis=1), axis=1)))
    tolerance = args.tolerance_share * size
    began = time.perf_counter()
    out = run([pmsc, "train", "--frames", w("train.npy"), "--out", w("model.pmsc"), "--tolerance", "%.6g" % tolerance]
              + positions + args.train.split())
    inspect = json.loads(run([pmsc, "inspect", w("model.pmsc"), "--json"]))
    report = {
        "points": int(train.shape[1]), "training_frames": int(len(train)), "stride": args.stride,
        "basis": inspect.get("basis"), "keys": len(inspect["key_indices"]),
        "body_size": size, "tolerance": tolerance, "train_wall_seconds": time.perf_counter() - began,
        "train_summary": [l.strip() for l in out.splitlines()
                          if l.strip().startswith(("basis", "key points", "sentinels"))],
        "takes": {name: replay(np, pmsc, w, evaluator, name, f"0-{lengths[name] - 1}:{args.stride}", size,
                               tolerance)
                  for name in names[1:]},
    }
    with open(w("report.json"), "w") as f:
        json.dump(report, f, indent=2)
    print(json.dumps(report, indent=2))
    bad = [name for name, r in report["takes"].items()
           if r["frames_over_tolerance"] or r["p995_point_error_over_size"] > args.check_p995]
    if args.check and bad:
        for name in bad:
            r = report["takes"][name]
            print("blender_rig: %s: %d frames over T, p99.5 point error %.4g of the body's size (--check-p995 %.4g)"
                  % (name, r["frames_over_tolerance"], r["p995_point_error_over_size"], args.check_p995),
                  file=sys.stderr)
        return 1
    return 0


def replay(np, pmsc, w, evaluator, take, span, size, tolerance):
    """Blender's full evaluation of the take's frames, then `pmsc run` over them: the figures."""
    began = time.perf_counter()
    run([pmsc, "export-frames", evaluator(take, w(take + ".full.log")), "--out", w(take + ".npy"), "--frames", span,
         "--threads", "1", "--quiet"])
    full_wall = time.perf_counter() - began
    out = w(take + ".run")
    shutil.rmtree(out, ignore_errors=True)
    began = time.perf_counter()
    # float32 frames, as Blender holds vertex positions: the run reconstructs from the basis in single
    # precision (pmsc run --basis-precision's default for float32 frames), half the bytes of double.
    run([pmsc, "run", "--model", w("model.pmsc"), "--evaluator", evaluator(take, w(take + ".run.log")), "--frames",
         span, "--out", out, "--threads", "1", "--quiet", "--dtype", "float32"])
    wall = time.perf_counter() - began
    full = np.load(w(take + ".npy"))
    frames = sorted(glob.glob(os.path.join(out, "frame.*.npy")))
    got = np.stack([np.load(f)[0].astype(np.float64) for f in frames])
    with open(glob.glob(os.path.join(out, "pmsc-run.*.json"))[0]) as f:
        stats = json.load(f)
    point_error = np.linalg.norm(got - full, axis=2)
    full_calls = [(n, s) for _, n, s in timings(w(take + ".full.log"))]
    logged = timings(w(take + ".run.log"))
    run_calls = [(n, s) for _, n, s in logged]
    full_per_frame = sum(s for _, s in full_calls) / len(full_calls)
    pmsc_per_frame = sum(s for _, s in run_calls) / len(full)
    key_calls = [s for _, _, s in first_calls(logged)]  # the keys, and the sentinels with them
    return {
        "frames": len(full),
        "hit_rate": stats["hit_rate"], "hits": stats["hits"], "blends": stats["blends"], "misses": stats["misses"],
        "p995_point_error_over_size": float(np.percentile(point_error, 99.5) / size),
        "largest_point_error_over_tolerance": float(point_error.max() / tolerance),
        # Over T beyond the child's own agreement: a point of a blend computed with the keys' stencils
        # and the same point of Blender's full evaluation differ by float32 rounding (about 1e-7 of
        # the body's size; the child prints it at start), which a point blended to exactly T shows.
        "frames_over_tolerance": int((point_error.max(axis=1) > tolerance + 1e-6 * size).sum()),
        "blender_seconds_per_frame": full_per_frame,
        "pmsc_child_seconds_per_frame": pmsc_per_frame,
        "speedup": full_per_frame / pmsc_per_frame,
        "key_call_seconds": sum(key_calls) / max(1, len(key_calls)),
        "calls_per_frame": len(run_calls) / len(full),
        "blender_export_wall_seconds": full_wall, "pmsc_run_wall_seconds": wall,
        "speedup_wall": full_wall / wall,
    }


if __name__ == "__main__":
    sys.exit(main())
