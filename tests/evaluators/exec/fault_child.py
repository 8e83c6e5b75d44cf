#!/usr/bin/env python3
"""An exec-protocol child for the tests: a small deforming surface (50 points x 3 channels,
20 frames) with one fault on request.

    fault_child.py [MODE[=FRAME]] ...
      crash=F    dies of SIGSEGV when asked for frame F (every time: a restarted child does too)
      hang=F     never answers frame F
      short=F    answers frame F with too few bytes, then exits
      nan=F      answers frame F with a NaN
      error=F    answers frame F with an error message and serves on
      exit       exits with code 3 before its hello (after a line on stderr)
      garbage    starts with something that is not a hello
      sleep=MS   busy-works MS milliseconds per request (a calculation that costs time)
"""
import os
import signal
import struct
import sys
import time

import numpy as np

POINTS, CHANNELS, FRAMES = 50, 3, 20


def values(frame, points):
    p = np.asarray(points, dtype=np.float64)[:, None]
    c = np.arange(CHANNELS, dtype=np.float64)[None, :]
    return np.sin(0.1 * frame + 0.01 * p + c) * (1.0 + 0.05 * frame)


def main():
    modes = dict(a.split("=", 1) if "=" in a else (a, "") for a in sys.argv[1:])
    at = {k: int(v) for k, v in modes.items() if k in ("crash", "hang", "short", "nan", "error")}
    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    if "exit" in modes:
        print("fault_child: no licence for this renderer", file=sys.stderr)
        sys.exit(3)
    if "garbage" in modes:
        stdout.write(b"Hello, I am a renderer\n" + b"\0" * 16)
        stdout.flush()
        time.sleep(5)
        return
    stdout.write(b"PMSCEXEC" + struct.pack("<IIQQ", 1, CHANNELS, POINTS, FRAMES))
    stdout.flush()
    while True:
        head = stdin.read(32)
        if len(head) < 32:
            return
        kind, _, frame, count, first = struct.unpack("<IIqQQ", head)
        if kind == 1:
            points = np.frombuffer(stdin.read(8 * count), dtype="<u8")
        else:
            points = np.arange(first, first + count, dtype=np.uint64)
        if "sleep" in modes:
            end = time.perf_counter() + int(modes["sleep"]) / 1000.0
            while time.perf_counter() < end:
                pass
        if at.get("crash") == frame:
            print(f"fault_child: segmentation fault in frame {frame}", file=sys.stderr, flush=True)
            os.kill(os.getpid(), signal.SIGSEGV)
        if at.get("hang") == frame:
            time.sleep(3600)
        if at.get("error") == frame:
            text = f"light 'key' has no shader in frame {frame}".encode()
            stdout.write(struct.pack("<IIQ", 1, 0, len(text)) + text)
            stdout.flush()
            continue
        v = values(frame, points)
        if at.get("nan") == frame:
            v[len(v) // 2, 1] = np.nan
        payload = v.astype("<f8").tobytes()
        stdout.write(struct.pack("<IIQ", 0, 0, v.size))
        if at.get("short") == frame:
            stdout.write(payload[: len(payload) // 2])
            stdout.flush()
            return
        stdout.write(payload)
        stdout.flush()


if __name__ == "__main__":
    main()
