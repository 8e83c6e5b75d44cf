#!/usr/bin/env python3
"""A complete exec-protocol child in Python: serves recorded frames from a .npy file.

    pmsc run --model M.pmsc --evaluator 'exec:python3 replay_child.py FRAMES.npy' --frames 0-99 --out OUT

Replace `frame_values` with your own calculation (a call into hython, mayapy, a renderer's
Python API): it gets a frame number and the point indices, and returns their values as a
(len(points), C) array. The protocol (docs/exec-protocol.md): a 32-byte hello, then per request
a 32-byte header (and, for a list, the indices), answered by a 16-byte header and the values.
"""
import struct
import sys

import numpy as np

HELLO = struct.Struct("<8sIIQQ")      # magic, version, channels, points, frames
REQUEST = struct.Struct("<IIqQQ")     # kind (1 list, 2 range), 0, frame, count, first
RESPONSE = struct.Struct("<IIQ")      # status (0 values, 1 error), 0, length
LIST, RANGE = 1, 2


def read_exactly(stream, size):
    data = stream.read(size)
    if len(data) != size:
        raise EOFError
    return data


def serve(frame_count, point_count, channels, frame_values):
    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    stdout.write(HELLO.pack(b"PMSCEXEC", 1, channels, point_count, frame_count))
    stdout.flush()
    while True:
        try:
            kind, _, frame, count, first = REQUEST.unpack(read_exactly(stdin, REQUEST.size))
        except EOFError:
            return  # pmsc is done with us
        if kind == LIST:
            points = np.frombuffer(read_exactly(stdin, 8 * count), dtype="<u8")
        else:
            points = np.arange(first, first + count, dtype=np.int64)
        try:
            values = np.ascontiguousarray(frame_values(frame, points), dtype="<f8")
        except Exception as error:  # say what went wrong and serve on
            text = f"{type(error).__name__}: {error}".encode()
            stdout.write(RESPONSE.pack(1, 0, len(text)) + text)
        else:
            stdout.write(RESPONSE.pack(0, 0, values.size))
            stdout.write(memoryview(values).cast("B"))
        stdout.flush()


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: replay_child.py FRAMES.npy  (frames, points, channels)")
    frames = np.load(sys.argv[1], mmap_mode="r")
    if frames.ndim != 3:
        sys.exit(f"replay_child.py: {sys.argv[1]} has shape {frames.shape}, not (frames, points, channels)")

    def frame_values(frame, points):
        return frames[frame][points]

    serve(frames.shape[0], frames.shape[1], frames.shape[2], frame_values)


if __name__ == "__main__":
    main()
