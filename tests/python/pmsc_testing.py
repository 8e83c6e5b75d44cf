"""Shared pieces of the Python module's tests: a small synthetic shot and the `pmsc` program."""
import os
import shutil
import subprocess
import tempfile
import unittest

import numpy as np

import pmsc


def synthetic_frames(frames=80, points=300, channels=3, seed=1, dtype=np.float32, novel=0):
    """Smooth global modes with a nonlinearity (like examples/synthetic, smaller): trainable, not exact.
    The last `novel` frames add a mode training never saw, so a replay has hits, blends and misses."""
    rng = np.random.default_rng(seed)
    modes = rng.standard_normal((6, points, channels))
    t = np.linspace(0.0, 6.0, frames)
    w = np.stack([np.sin(t * (k + 1) + k) for k in range(6)], axis=1)
    linear = np.einsum("fk,knc->fnc", w, modes)
    values = linear + 0.05 * np.sin(linear)
    if novel:
        extra = rng.standard_normal((points, channels))
        ramp = np.linspace(0.0, 1.0, novel)
        values[-novel:] += ramp[:, None, None] * 0.5 * extra
    return np.ascontiguousarray(values.astype(dtype))


def under_ci():
    """CI is set to anything but "", "false" or "0": the rule of every pmsc test (tests/common/MissingData.h)."""
    return os.environ.get("CI", "") not in ("", "false", "0")


def pmsc_binary():
    """Path of build/bin/pmsc, or None (the test skips; it fails under CI, under_ci())."""
    path = os.environ.get("PMSC_BINARY")
    if path and os.path.exists(path):
        return path
    if under_ci():
        raise AssertionError("PMSC_BINARY not set or missing: the CLI comparisons cannot run in CI")
    return None


def run_cli(*args, check=True):
    result = subprocess.run([pmsc_binary(), *map(str, args)], capture_output=True, text=True)
    if check and result.returncode != 0:
        raise AssertionError(f"pmsc {' '.join(map(str, args))} failed ({result.returncode}): {result.stderr}")
    return result


class TempDirTest(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="pmsc-python-test-")

    def tearDown(self):
        shutil.rmtree(self.dir, ignore_errors=True)

    def path(self, name):
        return os.path.join(self.dir, name)

    def cli_available(self):
        return pmsc_binary() is not None

    def require_cli(self):
        if pmsc_binary() is None:
            self.skipTest("build/bin/pmsc not built (PMSC_BINARY)")
