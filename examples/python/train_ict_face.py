#!/usr/bin/python3
"""Train PMSC on the ICT face from Python, replay a test take through the soft cache, and run the
evaluation engine with a Python evaluator.

    PYTHONPATH=build/python examples/python/train_ict_face.py ICT-FaceKit/FaceXModel --work face-py

The frames come from build/bin/pmsc_ict_frames (the face measurement of docs/face.md: 600 training frames,
seed 1; 300 test frames, seed 2), made once into --work. Any (frames, points, 3) array would do: the
frames of a Houdini or Maya export, numpy.stack of USD point arrays, ...
"""
import argparse
import os
import subprocess
import sys
import time

import numpy as np

import pmsc


def frames_file(args, name, count, seed):
    path = os.path.join(args.work, name)
    if not os.path.exists(path):
        print(f"making {path}: {count} frames of the ICT face rig (seed {seed})")
        subprocess.run([args.ict_frames, "--data", args.data, "--out", path, "--frames", str(count),
                        "--seed", str(seed)], check=True, stdout=subprocess.DEVNULL)
    return path


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("data", help="ICT-FaceKit FaceXModel folder")
    parser.add_argument("--work", default="face-py", help="folder for frames, model and outputs (default face-py)")
    parser.add_argument("--ict-frames", default=os.path.join(here, "..", "..", "build", "bin", "pmsc_ict_frames"),
                        help="the pmsc_ict_frames program (default build/bin/pmsc_ict_frames)")
    parser.add_argument("--train-frames", type=int, default=600)
    parser.add_argument("--test-frames", type=int, default=300)
    parser.add_argument("--max-keys", type=int, default=170)
    parser.add_argument("--tolerance", type=float, default=0.2376, help="0.5%% of the head's diagonal (docs/face.md)")
    parser.add_argument("--threads", type=int, default=0, help="engine threads (0 = every core)")
    args = parser.parse_args()
    os.makedirs(args.work, exist_ok=True)

    train = np.load(frames_file(args, "train.npy", args.train_frames, 1), mmap_mode="r")
    test = np.load(frames_file(args, "test.npy", args.test_frames, 2), mmap_mode="r")
    print(f"train {train.shape} {train.dtype}, test {test.shape} {test.dtype}")

    # 1. Train: the same options and the same model bytes as `pmsc train` (docs/face.md).
    start = time.perf_counter()
    cpu = time.process_time()
    model = pmsc.train(train, max_keys=args.max_keys, tolerance=args.tolerance)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    model.save(os.path.join(args.work, "face.pmsc"))
    print(f"train: M = {model.basis_size}, K = {model.key_count}, energy {model.energy_captured:.6f}, "
          f"eps [{model.eps[0]:.4f}, {model.eps[1]:.4f}], {wall:.2f} s wall ({cpu:.2f} s CPU)")
    for warning in model.training_report["warnings"]:
        print("  warning:", warning)

    # 2. Replay the test take: out is what `pmsc replay --out` writes, bit for bit.
    start = time.perf_counter()
    out, report = pmsc.replay(model, test, threads=args.threads)
    s = report["summary"]
    np.save(os.path.join(args.work, "out.npy"), out)
    print(f"replay: {s['frames']} frames in {time.perf_counter() - start:.2f} s; hit / blend / miss "
          f"{s['hit_rate']:.3f} / {s['blend_rate']:.3f} / {s['miss_rate']:.3f}; largest point error p50 / p99.5 / "
          f"max: PM {s['pm_max_point_error']['p50']:.4f} / {s['pm_max_point_error']['p995']:.4f} / "
          f"{s['pm_max_point_error']['max']:.4f}, soft-cached {s['soft_max_point_error']['p50']:.4f} / "
          f"{s['soft_max_point_error']['p995']:.4f} / {s['soft_max_point_error']['max']:.4f}")

    # 3. The engine with a Python evaluator: f(frame, point_indices) -> (P, 3). Here it reads the
    # recorded take; a studio's would call its rig. A hit asks only for the key points.
    asked = []
    def recorded(frame, points):
        asked.append(len(points))
        return test[frame, points]
    start = time.perf_counter()
    soft, run = pmsc.run(model, recorded, range(len(test)), threads=args.threads, dtype=test.dtype)
    r = run["summary"]
    print(f"run (Python evaluator): {r['frames_delivered']} frames in {time.perf_counter() - start:.2f} s, "
          f"{r['threads']} threads; hits {r['hits']}, blends {r['blends']}, misses {r['misses']}; "
          f"{len(asked)} evaluator calls, {sum(asked) / len(test):.0f} points per frame of {model.points}")
    assert soft.tobytes() == out.tobytes(), "the engine's output differs from replay's"
    print(f"outputs in {args.work}/: face.pmsc, out.npy")
    return 0


if __name__ == "__main__":
    sys.exit(main())
