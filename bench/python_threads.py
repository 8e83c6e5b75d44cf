#!/usr/bin/python3
"""A Python evaluator through the engine at 1 and 2 threads (issue 13: 2 threads must not be slower).

    PYTHONPATH=build/python bench/python_threads.py [--points 20000] [--frames 60] [--repeats 3]

The evaluator is a small "muscle rig" in NumPy: each point moves by J Gaussian influences whose
strengths follow the frame, out = rest + sum_j w_j(frame) exp(-|x - c_j|^2 / r^2) d_j, plus a twist
about an axis. Its work is in a handful of NumPy calls on (P, J) arrays, and NumPy releases the GIL
inside them: while one engine thread is in np.exp or a matrix product, another can run Python, so two
threads can overlap real work. (An evaluator that is pure Python bytecode would hold the GIL all the
time and could not speed up; the engine still stays correct, one call at a time.)

Two workloads: "misses" (eps = 0: every frame fails through as ~64 parallel chunks, each a Python
call) and "soft cache" (the model's own eps on a take with novel motion in its second half: hits cost
K key points, the rest fail through). Interleaved repetitions, medians; the load average is printed
before and after because wall-time ratios need a quiet machine.
"""
import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

import pmsc


class MuscleRig:
    def __init__(self, points, influences, frames, seed=7):
        rng = np.random.default_rng(seed)
        self.rest = rng.uniform(-1.0, 1.0, (points, 3))
        self.centres = rng.uniform(-1.0, 1.0, (influences, 3))
        self.directions = rng.standard_normal((influences, 3)) * 0.2
        t = np.arange(frames)[:, None]
        self.weights = np.sin(0.05 * t * (1 + np.arange(influences)[None, :] % 5) + np.arange(influences))
        self.novel = np.zeros(frames)
        self.inv_r2 = 1.0 / 0.35 ** 2

    def __call__(self, frame, points):
        x = self.rest[points]                                         # (P, 3)
        d2 = (x * x).sum(1)[:, None] - 2.0 * x @ self.centres.T + (self.centres ** 2).sum(1)[None, :]
        k = np.exp(-d2 * self.inv_r2)                                 # (P, J): the bulk, GIL released
        out = x + (k * self.weights[frame]) @ self.directions
        a = self.novel[frame] * x[:, 2]                               # a twist training never saw
        c, s = np.cos(a), np.sin(a)
        out[:, 0], out[:, 1] = c * out[:, 0] - s * out[:, 1], s * out[:, 0] + c * out[:, 1]
        return out


def loadavg():
    return os.getloadavg()[0]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--points", type=int, default=20000)
    parser.add_argument("--influences", type=int, default=128)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    total = 2 * args.frames
    rig = MuscleRig(args.points, args.influences, total)
    everything = np.arange(args.points)
    train = np.stack([rig(f, everything) for f in range(0, total, 2)])  # trained on every other frame
    model = pmsc.train(train, max_keys=120, tolerance=0.01)
    rig.novel[total // 2:] = np.linspace(0.0, 0.6, total - total // 2)  # the second half moves anew
    cases = {"misses": dict(eps=(0.0, 0.0)), "soft cache": dict()}

    before = loadavg()
    times = {(name, threads): [] for name in cases for threads in (1, 2)}
    cpu = {(name, threads): [] for name in cases for threads in (1, 2)}
    outputs = {}
    for _ in range(args.repeats):
        for name, options in cases.items():
            for threads in (1, 2):
                start, start_cpu = time.perf_counter(), time.process_time()
                out, report = pmsc.run(model, rig, range(total), threads=threads, **options)
                times[(name, threads)].append(time.perf_counter() - start)
                cpu[(name, threads)].append(time.process_time() - start_cpu)
                outputs.setdefault(name, out)
                assert out.tobytes() == outputs[name].tobytes(), "output depends on the thread count"
    after = loadavg()

    result = {"points": args.points, "frames": total, "model": {"M": model.basis_size, "K": model.key_count},
              "load_average_before": before, "load_average_after": after, "cpus": os.cpu_count()}
    for name, options in cases.items():
        one, two = statistics.median(times[(name, 1)]), statistics.median(times[(name, 2)])
        _, report = pmsc.run(model, rig, range(total), threads=1, **options)
        s = report["summary"]
        result[name] = {"seconds_1_thread": round(one, 3), "seconds_2_threads": round(two, 3),
                        "speedup_2_over_1": round(one / two, 3),
                        # CPU seconds of the whole process (all threads): the work plus GIL hand-offs
                        # and TBB's spinning; equal at 1 and 2 threads means no overhead was added.
                        "cpu_seconds_1_thread": round(statistics.median(cpu[(name, 1)]), 3),
                        "cpu_seconds_2_threads": round(statistics.median(cpu[(name, 2)]), 3),
                        "hits_blends_misses": [s["hits"], s["blends"], s["misses"]]}
    print(json.dumps(result, indent=2))
    return 0 if all(result[name]["speedup_2_over_1"] >= 1.0 for name in cases) else 1


if __name__ == "__main__":
    sys.exit(main())
