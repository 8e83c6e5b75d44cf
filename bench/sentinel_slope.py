#!/usr/bin/env python3
"""The sentinels' slope check, in a replica: which share of the covering radius to extrapolate the
steepest neighbouring slope by (pmsc::kSentinelSlopeShare).

For a model trained without sentinels (`--sentinels 0`), `pmsc replay --out` gives every frame's
soft-cached values. The replica places the sentinels as pmsc::farthestPointSentinels does (the
moving points that are not keys, farthest-point samples from the one that moves most, min(1024,
N / 16) of them), takes each one's 6 nearest sentinels, and refuses a frame that came back as a hit
or a local frame when PM's error e_i at a sentinel is over 0.8 T or

    e_i + c * r * max_j |e_i - e_j| / d_ij > T

for a share c (r the covering radius). A refused frame is computed in full (within T by the blend
guard). For each c the table gives, per frame set, the frames over T the check leaves and the frames
within T it refuses; c = 0 is the check at 0.8 T alone.

    # the face: a novelty_suite.py work folder whose variant V has --sentinels 0
    /usr/bin/python3 bench/sentinel_slope.py --train W/A-train.npy --model W/A-1.pmsc \\
        --sets W/A-validation.npy,W/A-novel.npy
    # light: a light_novelty.py work folder, its positions
    /usr/bin/python3 bench/sentinel_slope.py --train W/training.npy --positions W/positions.npy \\
        --model W/m1.pmsc --sets W/scattered.npy,W/path.npy,W/outside.npy

Without --positions the positions are the model's mean (a shape). Needs numpy and the pmsc Python
module (build/python). Exits 2 with one line on a bad argument or a failed command.
"""
import argparse
import os
import sys

from sentinel_choice import soft_errors  # the replay's soft-cached errors, cached beside the model


def fail(message):
    print("sentinel_slope: " + message, file=sys.stderr)
    sys.exit(2)


def farthest_points(np, positions, count, start):
    """Farthest-point sampling from `start`, as many as asked (or all)."""
    count = min(count, len(positions))
    chosen = [start]
    nearest = ((positions - positions[start]) ** 2).sum(1)
    for _ in range(count - 1):
        i = int(np.argmax(nearest))
        chosen.append(i)
        nearest = np.minimum(nearest, ((positions - positions[i]) ** 2).sum(1))
    return np.array(chosen), float(np.sqrt(nearest.max()))


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--train", required=True, help="the model's training frames (.npy)")
    p.add_argument("--model", required=True, help="a model trained with --sentinels 0")
    p.add_argument("--sets", required=True, help="frame files to replay, comma-separated")
    p.add_argument("--positions", help="the points' positions (.npy, N x 3 or more columns); default: the mean")
    p.add_argument("--shares", default="0,0.25,0.5,0.75", help="the shares c to try")
    p.add_argument("--bin", default="build/bin", help="folder of pmsc")
    p.add_argument("--python", default="build/python", help="folder of the pmsc Python module")
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
        shares = [float(c) for c in args.shares.split(",")]
    except ValueError:
        fail("--shares is comma-separated numbers")
    for path in [args.train, args.model] + args.sets.split(",") + ([args.positions] if args.positions else []):
        if not os.path.exists(path):
            fail("no " + path)
    q = np.load(args.train).astype(np.float64)
    model = pmsc.Model.load(args.model)
    n, tolerance = q.shape[1], model.tolerance
    if args.positions:
        positions = np.load(args.positions).astype(np.float64).reshape(n, -1)[:, :3]
    else:
        positions = np.asarray(model.mean).reshape(n, -1)[:, :3]
    motion = np.sqrt(((q - q.mean(0)) ** 2).sum(2).mean(0))
    moving = np.setdiff1d(np.where(motion >= 1e-3 * motion.max())[0], np.asarray(model.key_points))
    del q
    chosen, radius = farthest_points(np, positions[moving], min(1024, n // 16), int(np.argmax(motion[moving])))
    sentinels = moving[chosen]
    at = positions[sentinels]
    distance = np.sqrt(((at[:, None] - at[None]) ** 2).sum(2))
    near = np.argsort(distance, 1)[:, 1:7]
    near_distance = np.take_along_axis(distance, near, 1)
    cases = [(path, *soft_errors(np, args, args.model, path)) for path in args.sets.split(",")]
    print("%s: %d sentinels, covering radius %.4g, T %.4g" % (args.model, len(sentinels), radius, tolerance))
    print("| c | " + " | ".join("%s: over T left (of), within T refused (of)" % os.path.basename(c[0])
                               for c in cases) + " |")
    print("|---|" + "---|" * len(cases))
    for c in shares:
        cells = []
        for _, errors, routes in cases:
            left = over_all = refused = within = 0
            for f in range(len(errors)):
                if routes[f] not in ("hit", "local"):
                    continue
                e = errors[f][sentinels] / tolerance
                slope = (np.abs(e[:, None] - e[near]) / near_distance).max(1)
                passes = e.max() <= 0.8 and (e + c * radius * slope).max() <= 1.0
                over = errors[f].max() > tolerance * (1 + 1e-4)  # the float32 output's rounding
                over_all += over
                within += not over
                left += over and passes
                refused += (not over) and not passes
            cells.append("%d (%d), %d (%d)" % (left, over_all, refused, within))
        print("| %.2f | %s |" % (c, " | ".join(cells)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
