#!/usr/bin/env python3
"""Compares held-out schemes and calibration rules for `pmsc train --tolerance T` outside the engine.

    tools/calibration_holdout_experiment.py --model M.pmsc --train TRAIN.npy[,MORE.npy] \
        --tolerance T --test NAME=SET.npy [--test ...] [--holdout slices5,comp24_0.1] \
        [--rules max,conformal,threshold,significant0.25] [--key-error largest|rms] [--pymodule build/python]

It re-does what calibration does (pmsc/Calibration.cpp), in numpy: for every fold, the mean and the
M-basis of the held-in frames (M = the model's), the model's keys, and for each held-out frame its
key error e and its largest point error E under point multiplication. Then it sets eps_min by each
rule and replays the test sets against the model's own basis and keys (its eps are not used), so a
rule and a held-out scheme can be judged before they are written in C++.

Held-out schemes:
  slicesS        S contiguous slices (what `pmsc train --slices S` holds out)
  compK_TAU      one fold per Varimax-rotated leading basis vector (K of them): the frames whose
                 coordinate on it exceeds TAU times its largest, i.e. the frames that move that
                 motion, so the fold's model has (nearly) never seen it
Rules (T = --tolerance):
  max            T / the largest held-out ratio E/e
  conformal      T / the ratios' quantile at coverage 0.9
  threshold      the held-out crossing of T, between the two above (pmsc's `threshold`)
  significantA   threshold, capped at T / the largest ratio of held-out frames with E >= A T
First, per test set, the eps_min any single threshold must stay under (its first frame over T)
and must reach for 80% of the best threshold's hits. Then per test set: hits, the best single
threshold's hits (the most hits any eps gives with every hit under T, from the set's own errors),
frames whose soft-cached error exceeds T, and the worst soft-cached error in units of T.
Needs numpy and pmsc's Python module (to read the model).
"""
import argparse
import math
import sys

import numpy as np


def key_error(residual_norms, norm):
    if norm == "largest":
        return residual_norms.max(1)
    return np.sqrt((residual_norms**2).mean(1))


def held_out_scores(x, keys, m_basis, folds, norm):
    f, n, c = x.shape
    q = x.reshape(f, n * c)
    gram = q @ q.T
    es, big_es = [], []
    for out in folds:
        inside = np.setdiff1d(np.arange(f), out)
        g = gram[np.ix_(inside, inside)]
        row = g.mean(1)
        g = g - row[:, None] - row[None, :] + row.mean()
        w, v = np.linalg.eigh(g)
        order = np.argsort(w)[::-1]
        w, v = w[order], v[:, order]
        m = min(m_basis, len(inside) - 1, int((w > w[0] * 1e-12).sum()))
        jv = (v[:, :m] - v[:, :m].mean(0)) / np.sqrt(w[:m])
        u = q[inside].T @ jv
        uk = u.reshape(n, c, m)[keys].reshape(-1, m)
        d = q[out] - q[inside].mean(0)
        dk = d.reshape(len(out), n, c)[:, keys].reshape(len(out), -1)
        coords = np.linalg.lstsq(uk, dk.T, rcond=None)[0]
        rk = (dk - (uk @ coords).T).reshape(len(out), len(keys), c)
        r = (d - (u @ coords).T).reshape(len(out), n, c)
        es += list(key_error(np.sqrt((rk**2).sum(-1)), norm))
        big_es += list(np.sqrt((r**2).sum(-1)).max(1))
    return np.array(es), np.array(big_es)


def varimax(loadings, iterations=100, tol=1e-8):
    p, k = loadings.shape
    rot, last = np.eye(k), 0.0
    for _ in range(iterations):
        lr = loadings @ rot
        u, s, vt = np.linalg.svd(loadings.T @ (lr**3 - lr @ np.diag((lr**2).sum(0)) / p))
        rot = u @ vt
        if s.sum() < last * (1 + tol):
            break
        last = s.sum()
    return rot


def folds_for(scheme, x):
    f = len(x)
    if scheme.startswith("slices"):
        s = int(scheme[6:])
        return [np.arange(i * f // s, (i + 1) * f // s) for i in range(s)]
    if scheme.startswith("comp"):
        k, tau = scheme[4:].split("_")
        k, tau = int(k), float(tau)
        q = x.reshape(f, -1)
        qc = q - q.mean(0)
        w, v = np.linalg.eigh(qc @ qc.T)
        order = np.argsort(w)[::-1][:k]
        s, v = np.sqrt(np.maximum(w[order], 0)), v[:, order]
        coords = (v * s) @ varimax(qc.T @ (v / s))
        folds = []
        for j in range(coords.shape[1]):
            a = np.abs(coords[:, j])
            out = np.where(a > tau * a.max())[0]
            if 0 < len(out) < f - 2:
                folds.append(out)
        return folds
    sys.exit(f"unknown held-out scheme {scheme}")


def conformal_quantile(r, coverage):
    r = np.sort(r)
    n = len(r)
    rank = math.ceil((n + 1) * coverage * (1 - 1e-9))
    return r[-1] if rank > n else r[max(rank, 1) - 1]


def eps_by_rule(e, big_e, tol, rule):
    r = big_e / e
    floor, cap = tol / r.max(), tol / conformal_quantile(r, 0.9)
    if rule == "max":
        return floor
    if rule == "conformal":
        return cap
    bad = e[big_e > tol]
    eps = floor
    if len(bad):
        below = e[e < bad.min()]
        eps = max(floor, min(below.max() if len(below) else floor, cap))
    if rule.startswith("significant"):
        share = float(rule[len("significant"):])
        big = big_e >= share * tol
        if big.any():
            eps = min(eps, tol / r[big].max())
    return eps


def blend_band(e, big_e, ratio):
    return float(np.clip(ratio / np.median(big_e / e), 1.5, 2.0))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--model", required=True)
    ap.add_argument("--train", required=True, help="training frames, .npy, comma-separated in order")
    ap.add_argument("--tolerance", type=float, required=True)
    ap.add_argument("--test", action="append", default=[], help="NAME=FRAMES.npy")
    ap.add_argument("--holdout", default="slices5,comp24_0.1")
    ap.add_argument("--rules", default="max,conformal,threshold,significant0.25")
    ap.add_argument("--key-error", default="largest", choices=["largest", "rms"])
    ap.add_argument("--pymodule", default="build/python")
    a = ap.parse_args()
    sys.path.insert(0, a.pymodule)
    import pmsc  # noqa: E402

    model = pmsc.Model.load(a.model)
    keys, mean, basis = np.array(model.key_points), np.array(model.mean), np.array(model.basis)
    m_basis = model.basis_size
    x = np.concatenate([np.load(p).astype(np.float64) for p in a.train.split(",")])
    tests = {}
    for spec in a.test:
        name, path = spec.split("=", 1)
        y = np.load(path).astype(np.float64)
        f, n, c = y.shape
        uk = basis[keys].reshape(-1, m_basis)
        dk = (y - mean)[:, keys].reshape(f, -1)
        coords = np.linalg.pinv(uk) @ dk.T
        rk = (dk - (uk @ coords).T).reshape(f, len(keys), c)
        r = ((y - mean).reshape(f, -1) - (basis.reshape(n * c, m_basis) @ coords).T).reshape(f, n, c)
        tests[name] = (key_error(np.sqrt((rk**2).sum(-1)), a.key_error), np.sqrt((r**2).sum(-1)).max(1))
    tol = a.tolerance
    # What any single eps_min must be, whatever rule sets it: under the set's first frame over T
    # (else a frame over T is a hit), and at least the 80th percentile of the best threshold's hits.
    for name, (te, t_big) in tests.items():
        bad = te[t_big > tol]
        limit = bad.min() if len(bad) else np.inf
        ok = np.sort(te[te < limit])
        need = f"eps_min < {limit:.4g} (ratio T/eps > {tol / limit:.3f})" if len(bad) else "any eps_min"
        reach = (f"; 80% of the best {len(ok)} hits needs eps_min >= {ok[math.ceil(0.8 * len(ok)) - 1]:.4g} "
                 f"(ratio <= {tol / ok[math.ceil(0.8 * len(ok)) - 1]:.3f})" if len(ok) else "")
        print(f"{name}: {len(te)} frames; no frame over T needs {need}{reach}")
    for scheme in a.holdout.split(","):
        folds = folds_for(scheme, x)
        e, big_e = held_out_scores(x, keys, m_basis, folds, a.key_error)
        r = big_e / e
        print(f"{scheme}: {len(folds)} folds, {len(e)} held-out scores, ratio p50 {np.median(r):.3f} "
              f"max {r.max():.3f}, {int((big_e > tol).sum())} over T")
        for rule in a.rules.split(","):
            eps = eps_by_rule(e, big_e, tol, rule)
            band = blend_band(e, big_e, tol / eps)
            line = f"  {rule:16s} eps_min {eps:.4g} band {band:.2f}"
            for name, (te, t_big) in tests.items():
                w = np.clip((te - eps) / ((band - 1) * eps), 0, 1)
                soft = (1 - w) * t_big
                bad = te[t_big > tol]
                best = int((te < (bad.min() if len(bad) else np.inf)).sum())
                hits = int((te <= eps).sum())
                line += (f" | {name}: {hits} hits of best {best}, {int((soft > tol * (1 + 1e-12)).sum())} over T,"
                         f" worst {soft.max() / tol:.3f} T")
            print(line, flush=True)


if __name__ == "__main__":
    main()
