"""pmsc.replay: the same output bytes and report as `pmsc replay`, from an array or a .npy path."""
import io
import json
import unittest

import numpy as np

import pmsc
from pmsc_testing import TempDirTest, run_cli, synthetic_frames


def npy_bytes(array):
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


class ReplayTest(TempDirTest):
    @classmethod
    def setUpClass(cls):
        cls.train = synthetic_frames(frames=80, seed=1)
        cls.test = synthetic_frames(frames=80, seed=1, novel=30)   # float32: output rounded as the CLI's
        # No sentinels: a hit computes its keys alone, and eps=(1e9, 1e9) makes every frame one.
        cls.model = pmsc.train(cls.train, max_keys=30, tolerance=0.3, sentinels=0)

    def test_states_and_report(self):
        out, report = pmsc.replay(self.model, self.test, threads=2)
        self.assertEqual(out.dtype, np.float32)
        self.assertEqual(out.shape, self.test.shape)
        s = report["summary"]
        self.assertEqual((s["frames"], s["key_points"], s["basis"]), (80, 30, self.model.basis_size))
        states = [r["state"] for r in report["frames"]]
        self.assertIn("hit", states)
        self.assertIn("blend", states)
        self.assertIn("miss", states)                 # the novel mode is caught
        for row, frame in zip(report["frames"], range(80)):
            self.assertEqual(row["frame"], frame)
            if row["state"] == "miss":                # a miss is the recorded frame
                np.testing.assert_array_equal(out[frame], self.test[frame])
        # A hit is point multiplication of the recorded keys.
        hit = states.index("hit")
        pm = self.model.reconstruct(self.model.project(self.test[hit, self.model.key_points].astype(np.float64)))
        np.testing.assert_array_equal(out[hit], pm.astype(np.float32))

    def test_threads_and_eps(self):
        one, r1 = pmsc.replay(self.model, self.test, threads=1)
        two, r2 = pmsc.replay(self.model, self.test, threads=2)
        self.assertEqual(one.tobytes(), two.tobytes())
        self.assertEqual(r1["frames"], r2["frames"])
        _, everything = pmsc.replay(self.model, self.test, eps=(1e9, 1e9))
        self.assertEqual(everything["summary"]["hit_rate"], 1.0)

    def test_byte_identical_to_the_command_line(self):
        self.require_cli()
        model_path, frames_path = self.path("m.pmsc"), self.path("test.npy")
        self.model.save(model_path)
        for dtype in (np.float32, np.float64):
            with self.subTest(dtype=dtype.__name__):
                np.save(frames_path, self.test.astype(dtype))
                run_cli("replay", "--model", model_path, "--frames", frames_path, "--out", self.path("out.npy"),
                        "--report", self.path("report.json"), "--threads", 2, "--quiet")
                with open(self.path("out.npy"), "rb") as f:
                    cli_out = f.read()
                with open(self.path("report.json")) as f:
                    cli_report = json.load(f)
                for frames in (np.load(frames_path), frames_path):     # an array, and the file mapped
                    out, report = pmsc.replay(self.model, frames, threads=1)
                    self.assertEqual(npy_bytes(out), cli_out)
                    self.assertEqual(report["frames"], cli_report["frames"])
                    del report["summary"]["seconds"], cli_report["summary"]["seconds"]
                    self.assertEqual(report["summary"], cli_report["summary"])
                    with open(self.path("report.json")) as f:
                        cli_report = json.load(f)

    def test_regions_local_fail_through(self):
        # A version-2 model with regions: frames that do not hit are routed region by region.
        model = pmsc.train(self.train, max_keys=30, tolerance=0.3, regions=3)
        self.assertGreater(model.info["regions"], 0)
        out, report = pmsc.replay(model, self.test, threads=2)
        self.assertEqual(report["summary"]["regions"], model.info["regions"])
        self.assertIn("regions", report["frames"][0])
        whole, whole_report = pmsc.replay(model, self.test, whole_frame_fail_through=True)
        self.assertFalse(whole_report["summary"]["local_fail_through"])
        if self.cli_available():
            model.save(self.path("regions.pmsc"))
            np.save(self.path("test.npy"), self.test)
            run_cli("replay", "--model", self.path("regions.pmsc"), "--frames", self.path("test.npy"),
                    "--out", self.path("out.npy"), "--report", self.path("report.json"), "--quiet")
            with open(self.path("out.npy"), "rb") as f:
                self.assertEqual(npy_bytes(out), f.read())

    def test_array_layouts_read_in_place_or_converted(self):
        out, _ = pmsc.replay(self.model, self.test)
        # Fortran order and a big-endian copy hold the same values: converted once, same decisions.
        f_order, rf = pmsc.replay(self.model, np.asfortranarray(self.test))
        np.testing.assert_array_equal(f_order, out)
        swapped, _ = pmsc.replay(self.model, self.test.astype(">f8"))
        self.assertEqual(swapped.dtype, np.float64)


if __name__ == "__main__":
    unittest.main()
