#!/usr/bin/env python3
"""How many sentinels, and at what share of the tolerance: a replica of the soft cache's sentinel
check on the novelty suite's frames, for choosing pmsc::kDefaultSentinels and pmsc::kSentinelShare.

For each model of a novelty-suite work folder trained without sentinels (`--variant '--sentinels
0'`), `pmsc replay --out` gives every frame's soft-cached values; a frame that came back as a hit
or a local frame would be refused by S sentinels at share A when PM's soft-cached error at one of
them exceeds A * T (a refused frame is computed: within T by the blend guard). The sentinels are
farthest-point samples of the points that move in training (RMS motion at least 1e-3 of the
largest), as pmsc::farthestPointSentinels chooses them from the training mean. The table gives, per
(S, A), the frames over T the check would leave and the hits and local frames within T it would
refuse, on the validation and the novel frames.

    /usr/bin/python3 bench/novelty_suite.py --data FaceXModel --work W --sets A,B,C,D,E,F,G,H \\
        --variant '--sentinels 0' --variant '--energy 0.99999 --sentinels 0'
    /usr/bin/python3 bench/sentinel_choice.py --work W --sets A,B,C,D,E,F,G,H --models 1,2 \\
        [--counts 256,512,1024,2048] [--shares 0.6,0.7,0.8,0.9]

(--models: the variant numbers of the models without sentinels: W/SET-V.pmsc, 0 = the defaults.)
Needs numpy and the pmsc Python module (build/python). Exits 2 with one line on a bad argument or
a missing file.
"""
import argparse
import json
import os
import subprocess
import sys


def fail(message):
    print("sentinel_choice: " + message, file=sys.stderr)
    sys.exit(2)


def farthest_points(np, positions, count):
    """Farthest-point sampling from the first point, as many as asked (or all)."""
    count = min(count, len(positions))
    chosen = [0]
    nearest = ((positions - positions[0]) ** 2).sum(1)
    for _ in range(count - 1):
        i = int(np.argmax(nearest))
        chosen.append(i)
        nearest = np.minimum(nearest, ((positions - positions[i]) ** 2).sum(1))
    return np.array(chosen)


def soft_errors(np, args, model_path, frames_path):
    """Each frame's soft-cached error per point, and its route, from `pmsc replay --out`."""
    cache = model_path + "." + os.path.basename(frames_path) + ".soft.npz"
    if os.path.exists(cache):
        z = np.load(cache)
        return z["errors"], z["routes"]
    out, report = cache + ".npy", cache + ".json"
    done = subprocess.run([os.path.join(args.bin, "pmsc"), "replay", "--model", model_path, "--frames",
                           frames_path, "--report", report, "--out", out, "--quiet"],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if done.returncode != 0:
        fail("pmsc replay on %s exited %d: %s" % (model_path, done.returncode, done.stdout.strip()[-300:]))
    truth = np.load(frames_path)
    errors = np.sqrt(((np.load(out).astype(np.float64) - truth) ** 2).sum(2)).astype(np.float32)
    with open(report) as f:
        routes = np.array([("local" if r.get("local") else r["state"]) for r in json.load(f)["frames"]])
    np.savez(cache, errors=errors, routes=routes)
    os.remove(out)
    return errors, routes


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--work", required=True, help="a novelty_suite.py work folder")
    p.add_argument("--sets", required=True, help="sets, e.g. A,B,C")
    p.add_argument("--models", default="0", help="variant numbers of models without sentinels")
    p.add_argument("--bin", default="build/bin", help="folder of pmsc")
    p.add_argument("--python", default="build/python", help="folder of the pmsc Python module")
    p.add_argument("--counts", default="256,512,1024,2048")
    p.add_argument("--shares", default="0.6,0.7,0.8,0.9")
    args = p.parse_args()
    try:
        import numpy as np
    except ImportError:
        fail("needs numpy (run it with the system python3)")
    sys.path.insert(0, args.python)
    try:
        import pmsc
    except ImportError:
        fail("no pmsc Python module in " + args.python)
    try:
        counts = [int(c) for c in args.counts.split(",")]
        shares = [float(a) for a in args.shares.split(",")]
        variants = [int(v) for v in args.models.split(",")]
    except ValueError:
        fail("--counts, --shares and --models are comma-separated numbers")
    cases = []
    for name in args.sets.split(","):
        train_path = os.path.join(args.work, name + "-train.npy")
        if not os.path.exists(train_path):
            fail("no " + train_path)
        train = np.load(train_path)
        motion = np.sqrt(((train - train.mean(0)) ** 2).sum(2).mean(0))
        moving = np.where(motion >= 1e-3 * motion.max())[0]
        for v in variants:
            model_path = os.path.join(args.work, "%s-%d.pmsc" % (name, v))
            if not os.path.exists(model_path):
                fail("no " + model_path)
            model = pmsc.Model.load(model_path)
            positions = np.asarray(model.mean)[moving]
            for kind in ("validation", "novel"):
                errors, routes = soft_errors(np, args, model_path, os.path.join(args.work, "%s-%s.npy" % (name, kind)))
                cases.append((kind, model.tolerance, positions, moving, errors, routes))
    print("| sentinels | share of T | frames over T left (of) | validation hits and local frames refused | novel refused |")
    print("|---|---|---|---|---|")
    for count in counts:
        picks = [moving[farthest_points(np, positions, count)] for _, _, positions, moving, _, _ in cases]
        for share in shares:
            left = over_all = 0
            refused = {"validation": [0, 0], "novel": [0, 0]}
            for (kind, tolerance, _, _, errors, routes), pick in zip(cases, picks):
                candidate = (routes == "hit") | (routes == "local")
                over = errors.max(1) > tolerance * (1 + 1e-4)  # the float32 output's rounding
                passes = errors[:, pick].max(1) <= share * tolerance
                over_all += int((candidate & over).sum())
                left += int((candidate & over & passes).sum())
                refused[kind][0] += int((candidate & ~over & ~passes).sum())
                refused[kind][1] += int((candidate & ~over).sum())
            v, n = refused["validation"], refused["novel"]
            print("| %d | %.2f | %d (%d) | %d of %d (%.1f%%) | %d of %d |" % (
                count, share, left, over_all, v[0], v[1], 100.0 * v[0] / max(1, v[1]), n[0], n[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
