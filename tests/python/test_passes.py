"""examples/passes/bake_passes.py: a renderer's pass-by-pass loop over `pmsc reconstruct`, whose
output and states must equal `pmsc replay`'s, with and without local fail-through."""
import os
import subprocess
import sys

import numpy as np

from pmsc_testing import TempDirTest, pmsc_binary, run_cli, synthetic_frames

SCRIPT = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "passes", "bake_passes.py")


class BakePassesTest(TempDirTest):
    def bake(self, model, frames, *extra):
        cmd = [sys.executable, SCRIPT, "--pmsc", pmsc_binary(), "--model", model, "--frames", frames,
               "--work", self.path("work"), "--compare-replay"]
        if extra:
            cmd += ["--", *extra]
        return subprocess.run(cmd, capture_output=True, text=True)

    def test_region_model_equals_replay(self):
        self.require_cli()
        np.save(self.path("train.npy"), synthetic_frames(frames=80, seed=1, dtype=np.float64))
        np.save(self.path("test.npy"), synthetic_frames(frames=80, seed=1, novel=30, dtype=np.float64))
        run_cli("train", "--frames", self.path("train.npy"), "--out", self.path("m.pmsc"), "--max-keys", "30",
                "--tolerance", "0.3", "--regions", "3")
        for extra in ((), ("--whole-frame-fail-through",)):
            r = self.bake(self.path("m.pmsc"), self.path("test.npy"), *extra)
            self.assertEqual(r.returncode, 0, r.stdout + r.stderr)
            self.assertIn("byte for byte: True; states equal: True", r.stdout)
            self.assertIn("passes beyond the keys: ", r.stdout)

    def test_missing_frames_is_one_line_and_exit_2(self):
        self.require_cli()
        r = self.bake(self.path("nothing.pmsc"), self.path("nothing.npy"))
        self.assertEqual(r.returncode, 2, r.stderr)
        self.assertEqual(len(r.stderr.strip().splitlines()), 1, r.stderr)
        self.assertIn("nothing.npy", r.stderr)
