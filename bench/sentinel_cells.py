#!/usr/bin/env python3
"""How far a hit's largest point error can be from what its sentinels see: per sentinel cell.

The hit check (pmsc::HitCheck) computes the model's sentinels and lets a hit stand when PM is within
kSentinelShare * T (0.8 T) of each: it takes a sentinel's error to stand for the points around it,
up to a factor 1 / 0.8 = 1.25 (and the slope check). This script measures that factor on frames the
model did not fit. Each point belongs to its nearest sentinel's cell (in `--positions`, else the
model's mean); for a frame, a cell's ratio is the largest PM error among its points over PM's error
at its sentinel.

1. Held-out frames: the training frames cut into --folds contiguous slices; each slice is replayed
   through a model trained (`pmsc train --tolerance T` with the model's T, `--positions` when given,
   and --train) on the other slices. Per cell: the largest ratio over the held-out frames in which
   the cell's largest error reaches --level x T (smaller errors do not matter to T, and their
   ratios are noise).
2. The hits of replays (`TAKE.npy:REPORT.json`, a `pmsc replay --report` of the model): PM's error
   field in each hit, and what a check that scaled each sentinel's error by its cell's held-out
   ratio (at least 1.25) would have kept.

    /usr/bin/python3 bench/sentinel_cells.py --bin build/bin --model model.pmsc --frames train.npy \\
        [--positions rest.npy] [--folds 5] [--train '...'] [--work DIR] [TAKE.npy:REPORT.json ...]

Needs `import pmsc` (PYTHONPATH=build/python). Prints one JSON object. Exits 2 with one line on bad
arguments or a failed command.
"""
import argparse
import json
import os
import tempfile

import numpy as np

from suite_common import fail, run

try:
    import pmsc
except ImportError:
    fail("cannot import pmsc (set PYTHONPATH=build/python)")


def cells_of(positions, sentinels):
    """Each point's nearest sentinel (its position in `sentinels`), by brute force in chunks."""
    at = positions[sentinels]
    cell = np.empty(len(positions), dtype=np.int64)
    for i in range(0, len(positions), 2048):
        d = ((positions[i:i + 2048, None, :] - at[None]) ** 2).sum(-1)
        cell[i:i + 2048] = d.argmin(1)
    return cell


def point_errors(model, frame):
    """PM's error at every point of one frame (N,): the norm over the channels."""
    coords = model.project(frame[model.key_points])
    return np.linalg.norm(model.reconstruct(coords) - frame, axis=1)


def cell_max(errors, cell, count):
    out = np.zeros(count)
    np.maximum.at(out, cell, errors)
    return out


def held_out_ratios(args, model, cell, sentinels, work):
    """Per sentinel: the largest held-out ratio where its cell's error reaches --level T (NaN: never)."""
    frames = np.load(args.frames, mmap_mode="r")
    n, tolerance = len(frames), model.tolerance
    worst = np.full(len(sentinels), np.nan)
    reached = 0
    for k in range(args.folds):
        a, b = k * n // args.folds, (k + 1) * n // args.folds
        kept = os.path.join(work, "fold.npy")
        np.save(kept, np.concatenate([frames[:a], frames[b:]]))
        out = os.path.join(work, "fold.pmsc")
        cmd = [os.path.join(args.bin, "pmsc"), "train", "--frames", kept, "--out", out,
               "--tolerance", repr(tolerance)]
        cmd += (["--positions", args.positions] if args.positions else []) + args.train.split()
        run(cmd)
        fold = pmsc.Model.load(out)
        for f in range(a, b):
            e = point_errors(fold, np.asarray(frames[f], dtype=float))
            top = cell_max(e, cell, len(sentinels))
            at = e[sentinels]
            sel = top >= args.level * tolerance
            reached += int(sel.any())
            r = top[sel] / np.maximum(at[sel], 1e-300)
            worst[sel] = np.fmax(worst[sel], r)
        os.remove(kept)
    return worst, reached, n


def replay_hits(path_pair, model, cell, sentinels, bound):
    take, report = path_pair.split(":", 1)
    frames = np.load(take, mmap_mode="r")
    with open(report) as f:
        hits = [fr["frame"] for fr in json.load(f)["frames"] if fr["state"] == "hit"]
    tolerance = model.tolerance
    over = kept = kept_over = 0
    ratios = []
    for f in hits:
        e = point_errors(model, np.asarray(frames[f], dtype=float))
        at = e[sentinels]
        top = cell_max(e, cell, len(sentinels))
        sel = top >= 0.5 * tolerance
        ratios.extend((top[sel] / np.maximum(at[sel], 1e-300)).tolist())
        bad = e.max() > tolerance
        ok = bool((at * bound <= tolerance).all())
        over += int(bad)
        kept += int(ok)
        kept_over += int(ok and bad)
    q = np.quantile(ratios, [0.5, 0.9]).tolist() if ratios else [None, None]
    return {"take": take, "hits": len(hits), "hits_over_tolerance": over,
            "cell_ratio_p50": q[0], "cell_ratio_p90": q[1],
            "hits_kept_by_cell_ratios": kept, "of_them_over_tolerance": kept_over}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--bin", required=True)
    p.add_argument("--model", required=True)
    p.add_argument("--frames", required=True, help="the model's training frames (.npy)")
    p.add_argument("--positions", default="", help="the positions train was given (.npy), else the mean")
    p.add_argument("--folds", type=int, default=5)
    p.add_argument("--level", type=float, default=0.5, help="a cell counts where its error reaches this x T")
    p.add_argument("--train", default="", help="more `pmsc train` options, as one string")
    p.add_argument("--work", default="")
    p.add_argument("replays", nargs="*", help="TAKE.npy:REPORT.json")
    args = p.parse_args()
    if args.folds < 2:
        fail("--folds must be at least 2")
    for r in args.replays:
        if ":" not in r:
            fail("a replay is TAKE.npy:REPORT.json, got '" + r + "'")
    try:
        model = pmsc.Model.load(args.model)
    except pmsc.Error as e:
        fail(str(e))
    for path in [args.frames] + ([args.positions] if args.positions else []) + [r.split(":", 1)[0] for r in args.replays]:
        if not os.path.isfile(path):
            fail("no file " + path)
    sentinels = np.asarray(model.sentinel_points)
    if len(sentinels) == 0 or not model.tolerance > 0:
        fail(args.model + " has no sentinels (train it with a tolerance)")
    if args.positions:
        positions = np.load(args.positions)[..., :3].reshape(-1, 3).astype(float)
    else:
        positions = np.asarray(model.mean, dtype=float)
        if positions.shape[1] != 3:
            fail("the model's points are not positions: give --positions")
    if len(positions) != model.points:
        fail("--positions has %d points, the model %d" % (len(positions), model.points))
    cell = cells_of(positions, sentinels)
    work = args.work or tempfile.mkdtemp(prefix="sentinel-cells-")
    os.makedirs(work, exist_ok=True)
    worst, reached, n = held_out_ratios(args, model, cell, sentinels, work)
    seen = worst[~np.isnan(worst)]
    bound = np.where(np.isnan(worst), 1.25, np.maximum(worst, 1.25))
    out = {
        "model": args.model, "points": int(model.points), "sentinels": int(len(sentinels)),
        "points_per_cell": model.points / len(sentinels), "held_out_frames": n,
        "held_out_frames_reaching_level": reached, "cells_reaching_level": int(len(seen)),
        "held_out_cell_ratio": {"p50": float(np.median(seen)) if len(seen) else None,
                                "p90": float(np.quantile(seen, 0.9)) if len(seen) else None,
                                "max": float(seen.max()) if len(seen) else None},
        "replays": [replay_hits(r, model, cell, sentinels, bound) for r in args.replays],
    }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
