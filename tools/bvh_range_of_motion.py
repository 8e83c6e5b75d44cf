#!/usr/bin/env python3
"""Writes a range-of-motion take for a BVH skeleton: the training set a rigger would record.

    tools/bvh_range_of_motion.py TAKE.bvh ROM.bvh [--sweep DEG] [--mix DEG] [--mix-frames N] [--seed S]

The skeleton (HIERARCHY) is copied from TAKE.bvh; its motion is not read. The motion is:
  1. every joint alone, every rotation channel alone, swept -SWEEP..+SWEEP degrees and back in
     12 frames (the rest of the body at zero);
  2. N frames of every joint's rotation channels drawn uniformly in -MIX..+MIX degrees at once.
The root stays at its offset with zero rotation (pose it with skin:...:space=root to compare with
real takes). Pose it with `skin:ROM.bvh:body=tubes:space=root`; see docs/calibration.md.
"""
import argparse
import math
import random
import sys


def read_hierarchy(path):
    lines, channels = [], []  # channels: (joint index, name) per motion column
    joint = -1
    with open(path) as f:
        for line in f:
            if line.strip().startswith("MOTION"):
                break
            lines.append(line.rstrip("\n"))
            words = line.split()
            if words and words[0] in ("ROOT", "JOINT"):
                joint += 1
            if words and words[0] == "CHANNELS":
                channels += [(joint, name) for name in words[2:]]
    if not channels:
        sys.exit(f"bvh_range_of_motion: {path}: no CHANNELS in its HIERARCHY")
    return lines, channels


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("take")
    ap.add_argument("out")
    ap.add_argument("--sweep", type=float, default=75.0)
    ap.add_argument("--mix", type=float, default=45.0)
    ap.add_argument("--mix-frames", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frame-time", type=float, default=1.0 / 30)
    a = ap.parse_args()
    lines, channels = read_hierarchy(a.take)
    rotations = [i for i, (j, name) in enumerate(channels) if "rotation" in name and j > 0]
    frames = []
    for c in rotations:
        for k in range(12):
            row = [0.0] * len(channels)
            row[c] = a.sweep * math.sin(2 * math.pi * k / 12)
            frames.append(row)
    rng = random.Random(a.seed)
    for _ in range(a.mix_frames):
        row = [0.0] * len(channels)
        for c in rotations:
            row[c] = rng.uniform(-a.mix, a.mix)
        frames.append(row)
    with open(a.out, "w") as f:
        f.write("\n".join(lines) + "\n")
        f.write(f"MOTION\nFrames: {len(frames)}\nFrame Time: {a.frame_time:.6f}\n")
        for row in frames:
            f.write(" ".join(f"{v:.5f}" for v in row) + "\n")
    print(f"{a.out}: {len(frames)} frames, {len(rotations)} rotation channels")


if __name__ == "__main__":
    main()
