"""pmsc.run: the engine with a Python callable or a C++ evaluator spec."""
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
import unittest

import numpy as np

import pmsc
from pmsc_testing import TempDirTest, pmsc_binary, run_cli, synthetic_frames


class RunTest(TempDirTest):
    @classmethod
    def setUpClass(cls):
        cls.train = synthetic_frames(frames=80, seed=1)
        cls.test = synthetic_frames(frames=80, seed=1, novel=30).astype(np.float64)
        # No sentinels: a hit computes its keys alone, and eps=(1e9, 1e9) makes every frame one.
        cls.model = pmsc.train(cls.train, max_keys=30, tolerance=0.3, sentinels=0)

    def recorded(self, frame, points):
        return self.test[frame, points]

    def test_python_evaluator_equals_the_cpp_replay_evaluator(self):
        npy = self.path("test.npy")
        np.save(npy, self.test)
        cpp, cpp_report = pmsc.run(self.model, "replay:" + npy, threads=2)
        self.assertEqual(cpp.shape, self.test.shape)
        for threads in (1, 2):
            out, report = pmsc.run(self.model, self.recorded, range(80), threads=threads)
            self.assertEqual(out.tobytes(), cpp.tobytes())
            self.assertEqual(report["frames"], cpp_report["frames"])
            self.assertEqual(report["summary"]["frames_delivered"], 80)
        replayed, _ = pmsc.replay(self.model, self.test)
        self.assertEqual(cpp.tobytes(), replayed.tobytes())    # the engine's output is replay's

    def test_a_hit_evaluates_only_the_key_points(self):
        sizes, threads_seen = [], set()
        def evaluator(frame, points):
            sizes.append(len(points))
            threads_seen.add(threading.get_ident())
            return self.test[frame, points]
        out, report = pmsc.run(self.model, evaluator, 20, eps=(1e9, 1e9), threads=2, dtype=np.float32)
        self.assertEqual(out.dtype, np.float32)
        self.assertEqual(sizes, [self.model.key_count] * 20)
        self.assertEqual({r["state"] for r in report["frames"]}, {"hit"})

    def test_range_points_and_step(self):
        wanted = np.array([3, 1, 200])
        out, report = pmsc.run(self.model, self.recorded, range(10, 40, 3), points=wanted, threads=2)
        self.assertEqual(out.shape, (10, 3, 3))
        self.assertEqual([r["frame"] for r in report["frames"]], list(range(10, 40, 3)))
        full, _ = pmsc.run(self.model, self.recorded, range(10, 40, 3), threads=1)
        # A hit reconstructs only the wanted points (its own kernel: equal to the last bits or so).
        np.testing.assert_allclose(out, full[:, wanted], rtol=0, atol=1e-12)

    def test_evaluator_errors(self):
        def failing(frame, points):
            if frame == 5:
                raise ValueError("no pose for frame 5")
            return self.test[frame, points]
        with self.assertRaises(pmsc.EvaluatorError) as e:
            pmsc.run(self.model, failing, range(20), threads=2)
        message = str(e.exception)
        self.assertTrue(message.startswith("evaluator failed: frame 5: node '"), message)
        self.assertIn("evaluator 'python': ValueError: no pose for frame 5", message)
        self.assertIsInstance(e.exception.__cause__, ValueError)
        self.assertEqual(e.exception.exit_code, 3)

        out, report = pmsc.run(self.model, failing, range(20), threads=2, failure="continue")
        self.assertEqual([r["failed"] for r in report["frames"]], [f == 5 for f in range(20)])
        self.assertIn("ValueError: no pose for frame 5", report["frames"][5]["error"])
        self.assertEqual(report["summary"]["failed"], 1)
        self.assertTrue(np.isnan(out[5]).all())                        # a failed frame is NaN
        self.assertFalse(np.isnan(np.delete(out, 5, axis=0)).any())

        with self.assertRaisesRegex(pmsc.EvaluatorError, r"returned shape \(2,\) for 30 points x 3 channels"):
            pmsc.run(self.model, lambda f, p: np.zeros(2), 3)

    def test_bad_arguments(self):
        with self.assertRaisesRegex(pmsc.InputError, "needs frames=range"):
            pmsc.run(self.model, self.recorded)
        with self.assertRaisesRegex(pmsc.InputError, "unknown|known"):
            pmsc.run(self.model, "nosuch:thing", 3)
        with self.assertRaisesRegex(pmsc.InputError, "step must be > 0"):
            pmsc.run(self.model, self.recorded, range(10, 0, -1))

    def test_ctrl_c_stops_a_run(self):
        # The run waits with the GIL released but still notices SIGINT: the engine is cancelled and
        # KeyboardInterrupt raised, instead of running 100,000 frames.
        script = textwrap.dedent("""
            import signal, sys, time
            import numpy as np
            import pmsc
            from pmsc_testing import synthetic_frames
            signal.signal(signal.SIGINT, signal.default_int_handler)
            model = pmsc.train(synthetic_frames(frames=40, points=100), max_keys=10)
            def slow(frame, points):
                time.sleep(0.01)
                return np.zeros((len(points), 3))
            print("ready", flush=True)
            try:
                pmsc.run(model, slow, range(100000), threads=2, eps=(0, 0))
            except KeyboardInterrupt:
                print("interrupted", flush=True)
                sys.exit(0)
            sys.exit(1)
        """)
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([os.environ.get("PYTHONPATH", ""), os.path.dirname(__file__)]))
        child = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, env=env)
        self.assertEqual(child.stdout.readline().strip(), "ready")
        time.sleep(0.5)
        child.send_signal(signal.SIGINT)
        try:
            out, _ = child.communicate(timeout=30)
        finally:
            child.kill()
        self.assertEqual((child.returncode, out.strip()), (0, "interrupted"))


class EvaluatorSpecTest(TempDirTest):
    """Python and the command line offer the same calculations, through one registry."""

    def test_evaluators_are_the_command_lines(self):
        names = pmsc.evaluators()
        for name in ("replay", "skin", "synthetic", "cornell", "face", "face-control", "volume", "exec"):
            self.assertIn(name, names)
        if pmsc_binary() is None:
            self.skipTest("the pmsc program is not built")
        listed = [line.split()[0] for line in run_cli("evaluators").stdout.splitlines()]
        self.assertEqual(names, listed)

    def train_on(self, spec, frames, **options):
        """A model trained on the spec's first frames, exported by `pmsc export-frames`."""
        npy = self.path("frames.npy")
        run_cli("export-frames", spec, "--out", npy, "--frames", f"0-{frames - 1}", "--quiet")
        return np.load(npy), pmsc.train(np.load(npy), **options)

    def test_run_accepts_the_synthetic_spec(self):
        if pmsc_binary() is None:
            self.skipTest("the pmsc program is not built")
        spec = "synthetic:grid=12:frames=60:seed=3"
        frames, model = self.train_on(spec, 40, max_keys=24, tolerance=0.3)
        out, report = pmsc.run(model, spec, range(40, 60), threads=2)
        self.assertEqual(out.shape, (20, 144, 3))
        self.assertEqual([row["frame"] for row in report["frames"]], list(range(40, 60)))
        with self.assertRaises(pmsc.InputError):
            pmsc.run(model, "synthetic:grid=12:frames=60:bogus=1")

    def test_run_accepts_the_volume_spec_on_a_demo_density(self):
        if pmsc_binary() is None:
            self.skipTest("the pmsc program is not built")
        demo = self.path("volume")
        run_cli("demo", "volume", "--quick", "--quiet", "--out", demo)
        spec = "volume:" + os.path.join(demo, "density.vdb") + ":samples=2"
        frames, model = self.train_on(spec, 24, max_keys=60, tolerance=0.05)
        out, report = pmsc.run(model, spec, range(24), threads=2)
        self.assertEqual(out.shape, frames.shape)
        self.assertEqual(report["summary"]["frames_delivered"], 24)
        # Frames the model was trained on come back close to the full calculation's values.
        scale = np.abs(frames).max()
        self.assertLess(np.abs(out - frames).max() / scale, 0.05)


if __name__ == "__main__":
    unittest.main()
