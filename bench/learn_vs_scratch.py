#!/usr/bin/env python3
"""`pmsc learn` against `pmsc train` from scratch on the union, on the ICT face take.

For each base size B: train on frames [0, B) of take seed 1 (with --learn-rank), `pmsc learn`
with frames [B, B + NEW), and `pmsc train` from scratch on [0, B + NEW) with the same options;
replay both models on held-out takes (other seeds) and print, per take, the p99.5 over frames of
PM's largest point error and of the soft-cached error (learn / scratch), and the wall times of
`pmsc learn` and of the scratch `pmsc train` (medians of --repeats runs, alternated).

    /usr/bin/python3 bench/learn_vs_scratch.py --data ICT-FaceKit/FaceXModel --bin build/bin \\
        --work /tmp/learn-bench --sizes 300,600,1200 --new 300 --repeats 3

Needs numpy (the system python3). Exits 2 with one line on bad arguments or a failed command.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time


def fail(message):
    print("learn_vs_scratch: " + message, file=sys.stderr)
    sys.exit(2)


def run(cmd):
    start = time.monotonic()
    done = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seconds = time.monotonic() - start
    if done.returncode != 0:
        fail("'" + " ".join(cmd) + "' exited " + str(done.returncode) + ": " + done.stdout.strip()[-400:])
    return seconds, done.stdout


def frames_file(args, path, count, seed):
    if not os.path.exists(path):
        run([os.path.join(args.bin, "pmsc_ict_frames"), "--data", args.data, "--out", path, "--frames",
             str(count), "--seed", str(seed), "--dtype", "float32"])
    return path


def slices(args, np, pool, base):
    names = {}
    for tag, first, last in (("base", 0, base), ("new", base, base + args.new), ("union", 0, base + args.new)):
        path = os.path.join(args.work, "%s%d.npy" % (tag, base))
        if not os.path.exists(path):
            np.save(path, pool[first:last])
        names[tag] = path
    return names


def replay(args, model, take):
    report = model + "." + os.path.basename(take) + ".json"
    run([os.path.join(args.bin, "pmsc"), "replay", "--model", model, "--frames", take, "--report", report,
         "--quiet"])
    with open(report) as f:
        s = json.load(f)["summary"]
    return {"pm": s["pm_max_point_error"]["p995"], "soft": s["soft_max_point_error"]["p995"],
            "hit": s["hit_rate"], "M": s["basis"]}


def measure(args, np, pool, base):
    f = slices(args, np, pool, base)
    pmsc = os.path.join(args.bin, "pmsc")
    train = ["--max-keys", str(args.max_keys), "--tolerance", str(args.tolerance), "--learn-rank",
             str(args.learn_rank), "--quiet"]
    day1 = os.path.join(args.work, "day1_%d.pmsc" % base)
    learned = os.path.join(args.work, "learned_%d.pmsc" % base)
    scratch = os.path.join(args.work, "scratch_%d.pmsc" % base)
    run([pmsc, "train", "--frames", f["base"], "--out", day1] + train)
    learn_s, scratch_s, learn_out = [], [], ""
    for _ in range(args.repeats):
        seconds, learn_out = run([pmsc, "learn", "--model", day1, "--frames", f["new"], "--out", learned, "--quiet"])
        learn_s.append(seconds)
        seconds, _ = run([pmsc, "train", "--frames", f["union"], "--out", scratch] + train)
        scratch_s.append(seconds)
    takes = {take: (replay(args, learned, take), replay(args, scratch, take)) for take in args.takes}
    return statistics.median(learn_s), statistics.median(scratch_s), takes, learn_out


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--data", required=True, help="ICT-FaceKit FaceXModel folder")
    p.add_argument("--bin", default="build/bin")
    p.add_argument("--work", default="/tmp/learn-bench")
    p.add_argument("--sizes", default="300", help="base training sizes B, comma-separated")
    p.add_argument("--new", type=int, default=300, help="frames pmsc learn adds")
    p.add_argument("--take-seeds", default="2,3", help="seeds of the held-out takes (300 frames each)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--learn-rank", type=int, default=96)
    p.add_argument("--max-keys", type=int, default=170)
    p.add_argument("--tolerance", type=float, default=0.2376, help="0.5%% of the head diagonal")
    args = p.parse_args()
    try:
        import numpy as np
    except ImportError:
        fail("needs numpy: run it with the system python3 (/usr/bin/python3)")
    try:
        sizes = [int(s) for s in args.sizes.split(",")]
        seeds = [int(s) for s in args.take_seeds.split(",")]
    except ValueError:
        fail("--sizes and --take-seeds are comma-separated integers")
    if min(sizes) < 2 or args.new < 2 or args.repeats < 1:
        fail("sizes and --new must be >= 2, --repeats >= 1")
    if not os.path.isdir(args.data):
        fail(args.data + " is not a folder")
    os.makedirs(args.work, exist_ok=True)
    pool_path = frames_file(args, os.path.join(args.work, "pool%d.npy" % (max(sizes) + args.new)),
                            max(sizes) + args.new, 1)
    pool = np.load(pool_path, mmap_mode="r")
    args.takes = [frames_file(args, os.path.join(args.work, "take%d.npy" % s), 300, s) for s in seeds]

    print("| B + new | take | M learn / scratch | PM p99.5 learn / scratch (ratio) | soft p99.5 learn / scratch"
          " (ratio) | hits learn / scratch | learn s | scratch s | time ratio |")
    print("|---|---|---|---|---|---|---|---|---|")
    for base in sizes:
        learn_s, scratch_s, takes, learn_out = measure(args, np, pool, base)
        for take, (l, s) in takes.items():
            print("| %d + %d | %s | %d / %d | %.4f / %.4f (%.3f) | %.4f / %.4f (%.3f) | %.1f%% / %.1f%% | %.2f | %.2f"
                  " | %.3f |" % (base, args.new, os.path.basename(take), l["M"], s["M"], l["pm"], s["pm"],
                                 l["pm"] / s["pm"], l["soft"], s["soft"], l["soft"] / s["soft"], 100 * l["hit"],
                                 100 * s["hit"], learn_s, scratch_s, learn_s / scratch_s))
        sys.stdout.flush()
        print("<!-- " + learn_out.strip().splitlines()[0] + " -->", file=sys.stderr)


if __name__ == "__main__":
    main()
