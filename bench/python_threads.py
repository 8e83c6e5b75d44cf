#!/usr/bin/python3
"""A Python evaluator through the engine at 1 and 2 threads (goal: 2 threads must not be slower).

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
before and after because wall-time ratios need a quiet machine (under load, the kernel's fair share
goes to the process group, not the thread, so no thread count gets more CPU). "evaluator_gil_fraction"
does not depend on the load: the share of a call spent in the interpreter (see gil_fraction()).
"""
import argparse
import json
import os
import statistics
import sys
import threading
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


def gil_fraction(rig, points):
    """An estimate of the share of a Python evaluator call that holds the GIL: the CPU time of a call
    on one point (interpreter and NumPy dispatch only, all under the GIL) over that of a call on a
    default fail-through chunk (N/8 points). Ratios of one thread's CPU times, so the machine's load
    does not enter. Amdahl then bounds 2 threads on an idle machine by 1 / (p + (1 - p) / 2)."""
    def cost(indices):
        samples = []
        for frame in range(min(21, len(rig.weights))):
            start = time.thread_time()
            rig(frame, indices)
            samples.append(time.thread_time() - start)
        return statistics.median(samples)
    p = cost(np.arange(1)) / cost(np.arange((points + 7) // 8))
    return p, 1.0 / (p + (1.0 - p) / 2.0)


def machine_parallelism(repeats):
    """Control without pmsc: the same NumPy work (np.exp on 2M values, GIL released) split over 1 or
    2 plain Python threads. What 2 threads can gain on this machine right now; 1.0 under heavy load."""
    a = np.random.default_rng(1).random(2_000_000)
    def work(n):
        for _ in range(n):
            np.exp(a)
    times = {1: [], 2: []}
    for _ in range(repeats):
        for threads in (1, 2):
            workers = [threading.Thread(target=work, args=(80 // threads,)) for _ in range(threads)]
            start = time.perf_counter()
            for w in workers:
                w.start()
            for w in workers:
                w.join()
            times[threads].append(time.perf_counter() - start)
    return statistics.median(times[1]) / statistics.median(times[2])


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
    control_before = machine_parallelism(args.repeats)
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
    control_after = machine_parallelism(args.repeats)

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
    result["control_numpy_threads_2_over_1"] = [round(control_before, 3), round(control_after, 3)]
    p, bound = gil_fraction(rig, args.points)
    result["evaluator_gil_fraction"] = round(p, 3)
    result["idle_machine_bound_2_over_1"] = round(bound, 2)
    print(json.dumps(result, indent=2))
    return 0 if all(result[name]["speedup_2_over_1"] >= 1.0 for name in cases) else 1


if __name__ == "__main__":
    sys.exit(main())
