#!/usr/bin/env python3
"""Sentinels spent where held-out PM errors are largest, in a replica: do they catch the patches
the evenly spread sentinels miss?

For a model trained without sentinels (`--sentinels 0`) and the frames `pmsc replay --out` gives
back, a frame that came back as a hit or a local frame is refused when PM's error at a sentinel
exceeds 0.8 T. Rules: the evenly spread sentinels (farthest-point samples of the moving points that
are not keys, min(1024, N / 16), as pmsc::farthestPointSentinels), twice as many, and the even ones
plus E more by farthest-point sampling weighted by w = max((h / max h)^a, floor), h each point's
largest error under PM of held-out training frames (five interleaved folds, the fold's principal
basis of the model's M, the model's keys). The table counts the frames over T each rule leaves and
the frames within T it refuses.

    /usr/bin/python3 bench/sentinel_weighting.py --train W/training.npy --positions W/positions.npy \
        --model W/m1.pmsc --sets W/scattered.npy,W/path.npy,W/outside.npy

Needs numpy and the pmsc Python module (--python, default build/python).
"""
import argparse, os, sys
import numpy as np

from sentinel_choice import soft_errors  # the replay's soft-cached errors, cached beside the model


def fps(positions, count, weight=None, start=None, chosen=None):
    n = len(positions)
    w = np.ones(n) if weight is None else weight
    if chosen is None or len(chosen) == 0:
        first = int(np.argmax(w)) if start is None else start
        chosen = [first]
    chosen = list(chosen)
    nearest = np.full(n, np.inf)
    for c in chosen:
        nearest = np.minimum(nearest, ((positions - positions[c]) ** 2).sum(1))
    while len(chosen) < count:
        i = int(np.argmax(w * np.sqrt(nearest)))
        chosen.append(i)
        nearest = np.minimum(nearest, ((positions - positions[i]) ** 2).sum(1))
    return np.array(chosen)


def heldout_error(q, keys, m, folds=5):
    """Per-point largest error of PM (same keys, fold PCA basis of size m) over held-out frames."""
    f = len(q)
    flat = q.reshape(f, -1)
    n, c = q.shape[1], q.shape[2]
    h = np.zeros(n)
    idx = np.arange(f)
    for k in range(folds):
        test = idx[k::folds]
        train = np.setdiff1d(idx, test)
        mean = flat[train].mean(0)
        u, s, vt = np.linalg.svd(flat[train] - mean, full_matrices=False)
        mm = min(m, len(train) - 1)
        basis = vt[:mm].T.reshape(n, c, mm)
        kb = basis[keys].reshape(-1, mm)
        pinv = np.linalg.pinv(kb)
        for t in test:
            coords = pinv @ (q[t][keys] - mean.reshape(n, c)[keys]).reshape(-1)
            rec = mean.reshape(n, c) + basis @ coords
            e = np.sqrt(((rec - q[t]) ** 2).sum(1))
            h = np.maximum(h, e)
    return h


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--train", required=True)
    p.add_argument("--positions", required=True)
    p.add_argument("--model", required=True)
    p.add_argument("--sets", required=True)
    p.add_argument("--bin", default="build/bin")
    p.add_argument("--python", default="build/python")
    p.add_argument("--share", type=float, default=0.8)
    a = p.parse_args()
    sys.path.insert(0, a.python)
    global pmsc
    import pmsc
    q = np.load(a.train).astype(np.float64)
    pos = np.load(a.positions).astype(np.float64).reshape(q.shape[1], -1)[:, :3]
    model = pmsc.Model.load(a.model)
    T = model.tolerance
    keys = np.asarray(model.key_points)
    motion = np.sqrt(((q - q.mean(0)) ** 2).sum(2).mean(0))
    moving = np.where(motion >= 1e-3 * motion.max())[0]
    moving = np.setdiff1d(moving, keys)
    P = pos[moving]
    hcache = a.model + ".heldout.npy"
    if os.path.exists(hcache):
        h = np.load(hcache)
    else:
        h = heldout_error(q, keys, model.basis_size)
        np.save(hcache, h)
    hm = h[moving]
    print("T", T, "M", model.basis_size, "moving", len(moving), "heldout max/T %.3f p50/T %.3f" % (hm.max() / T, np.median(hm) / T))
    cases = [soft_errors(np, a, a.model, s) for s in a.sets.split(",")]
    rules = {}
    start = int(np.argmax(motion[moving]))
    basecount = min(1024, q.shape[1] // 16)
    base = fps(P, basecount, start=start)
    rules["uniform%d" % basecount] = moving[base]
    rules["uniform%d" % (2 * basecount)] = moving[fps(P, 2 * basecount, start=start)]
    for alpha in (1.0, 2.0):
        for floor in (0.0, 0.1):
            w = np.maximum((hm / hm.max()) ** alpha, floor)
            for extra in (64, 128, 256):
                rules["u%d+w%d a%.0f f%.1f" % (basecount, extra, alpha, floor)] = moving[fps(P, basecount + extra, weight=w, chosen=base)]
    for name, pick in rules.items():
        left = over_all = refused = cand_ok = 0
        worst = 0
        for errors, routes in cases:
            cand = (routes == "hit") | (routes == "local")
            over = errors.max(1) > T * (1 + 1e-4)
            passes = errors[:, pick].max(1) <= a.share * T
            over_all += int((cand & over).sum())
            leftm = cand & over & passes
            left += int(leftm.sum())
            if leftm.any():
                worst = max(worst, errors[leftm].max() / T)
            refused += int((cand & ~over & ~passes).sum())
            cand_ok += int((cand & ~over).sum())
        print("%-28s left %d of %d (worst %.3f T), refused %d of %d good" % (name, left, over_all, worst, refused, cand_ok))


if __name__ == "__main__":
    main()
