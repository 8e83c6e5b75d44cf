"""Errors are Python exceptions carrying the command line's one-line messages and exit codes."""
import unittest

import numpy as np

import pmsc
from pmsc_testing import TempDirTest, run_cli, synthetic_frames


class ErrorTest(TempDirTest):
    @classmethod
    def setUpClass(cls):
        cls.frames = synthetic_frames(frames=40, points=100)
        cls.model = pmsc.train(cls.frames, max_keys=10)

    def cli_line(self, *args):
        """The line `pmsc` prints on stderr, without its "pmsc: " prefix, and the exit code."""
        result = run_cli(*args, check=False)
        line = result.stderr.strip().splitlines()[-1]
        self.assertTrue(line.startswith("pmsc: "), result.stderr)
        return line[len("pmsc: "):], result.returncode

    def assert_same_as_cli(self, call, exception, *cli_args):
        message, code = self.cli_line(*cli_args)
        with self.assertRaises(exception) as e:
            call()
        self.assertEqual(str(e.exception), message)
        self.assertEqual(e.exception.exit_code, code)

    def test_model_files(self):
        self.require_cli()
        missing = self.path("missing.pmsc")
        self.assert_same_as_cli(lambda: pmsc.Model.load(missing), pmsc.InputError, "inspect", missing)
        corrupt = self.path("corrupt.pmsc")
        data = bytearray(self.model.to_bytes())
        data[200] ^= 0x40
        with open(corrupt, "wb") as f:
            f.write(bytes(data))
        self.assert_same_as_cli(lambda: pmsc.Model.load(corrupt), pmsc.InputError, "inspect", corrupt)
        self.assertIsInstance(pmsc.InputError("x"), ValueError)

    def test_frame_files(self):
        self.require_cli()
        bad = self.frames.copy()
        bad[3, 7, 1] = np.nan
        npy = self.path("nan.npy")
        np.save(npy, bad)
        model = self.path("m.pmsc")
        self.model.save(model)
        self.assert_same_as_cli(lambda: pmsc.replay(self.model, npy), pmsc.InputError,
                                "replay", "--model", model, "--frames", npy, "--report", self.path("r.json"))
        self.assert_same_as_cli(lambda: pmsc.train(npy), pmsc.InputError,
                                "train", "--frames", npy, "--out", self.path("x.pmsc"), "--quiet")
        # The same NaN in an array: the same words, the array named instead of the file.
        with self.assertRaises(pmsc.InputError) as e:
            pmsc.replay(self.model, bad)
        self.assertEqual(str(e.exception), "frames: NaN at frame 3, point 7, channel 1 (frames must be finite)")

    def test_unwritable_output(self):
        with self.assertRaises(pmsc.IoError) as e:
            self.model.save(self.path("no/such/folder/m.pmsc"))
        self.assertTrue(str(e.exception).startswith("cannot write output: "), str(e.exception))
        self.assertEqual(e.exception.exit_code, 4)

    def test_arrays(self):
        with self.assertRaisesRegex(pmsc.InputError, r"^frames: shape \(40, 300\) has 2 dimensions"):
            pmsc.train(self.frames.reshape(40, 300))
        with self.assertRaisesRegex(pmsc.InputError, "has a zero dimension"):
            pmsc.replay(self.model, self.frames[:0])
        with self.assertRaisesRegex(pmsc.InputError, "unsupported dtype complex128"):
            pmsc.replay(self.model, self.frames.astype(complex))
        with self.assertRaisesRegex(pmsc.InputError, "frames: frames have 50 points x 3 channels, but the model"):
            pmsc.replay(self.model, self.frames[:, :50])
        with self.assertRaisesRegex(pmsc.InputError, r"^train: max keys must be in \[1, 100\]"):
            pmsc.train(self.frames, max_keys=1000)
        with self.assertRaisesRegex(pmsc.InputError, "is not (K, C)|is not \\(K, C\\)"):
            self.model.project(np.zeros(5))
        with self.assertRaisesRegex(pmsc.InputError, "selector: 'nope'"):
            pmsc.train(self.frames, selector="nope")
        with self.assertRaisesRegex(pmsc.InputError, "^coverage needs calibration threshold or conformal"):
            pmsc.train(self.frames, tolerance=0.1, calibration="max", coverage=0.8)
        with self.assertRaisesRegex(pmsc.InputError, "^basis and energy both set M: give one"):
            pmsc.learn(self.model, self.frames, basis=4, energy=0.9)
        with self.assertRaisesRegex(pmsc.InputError, "^calibration: 'tight' is not threshold, max or conformal"):
            pmsc.learn(self.model, self.frames, calibration="tight")
        with self.assertRaisesRegex(pmsc.InputError, "frames: frames have 50 points x 3 channels, but the model"):
            pmsc.learn(self.model, self.frames[:, :50])


if __name__ == "__main__":
    unittest.main()
