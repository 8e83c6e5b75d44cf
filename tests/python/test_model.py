"""pmsc.train and pmsc.Model: sizes, the runtime against NumPy's own arithmetic, files, and the
same model bytes as `pmsc train`."""
import pickle
import unittest

import numpy as np

import pmsc
from pmsc_testing import TempDirTest, run_cli, synthetic_frames


class ModelTest(TempDirTest):
    @classmethod
    def setUpClass(cls):
        cls.frames = synthetic_frames(dtype=np.float64)
        cls.model = pmsc.train(cls.frames, max_keys=30, tolerance=0.05, seed=3)

    def test_sizes_and_views(self):
        m = self.model
        self.assertEqual((m.points, m.channels, m.train_frames), (300, 3, 80))
        self.assertEqual(m.key_count, 30)
        self.assertEqual(m.mean.shape, (300, 3))
        self.assertEqual(m.basis.shape, (300, 3, m.basis_size))
        self.assertEqual(m.projector.shape, (m.basis_size, 30 * 3))
        self.assertEqual(len(set(m.key_points.tolist())), 30)
        self.assertFalse(m.mean.flags.writeable)           # views of the model, not copies
        self.assertFalse(m.basis.flags.owndata)
        np.testing.assert_allclose(m.mean, self.frames.mean(axis=0), atol=1e-12)
        self.assertGreater(m.eps[1], m.eps[0])
        self.assertEqual(m.info["key_points"], 30)
        self.assertEqual(m.training_report["warnings"], [])

    def test_shared_channels_model_is_its_own_arithmetic(self):
        # Channels sharing the basis: basis (N, 1, M), projector (M, K), M x C
        # coordinates per frame; channel c = mean_c + basis @ coords_c.
        f = self.frames
        m = pmsc.train(f, max_keys=30, basis=6, shared_channels=True, seed=3)
        self.assertTrue(m.info["shared_channels"])
        self.assertEqual(m.basis.shape, (300, 1, 6))
        self.assertEqual(m.projector.shape, (6, 30))
        keys = f[:, m.key_points]                                       # (F, K, C)
        coords = m.project(keys)
        self.assertEqual(coords.shape, (len(f), 6 * 3))
        expect = np.einsum("mk,fkc->fmc", m.projector, keys - m.mean[m.key_points]).reshape(len(f), -1)
        np.testing.assert_allclose(coords, expect, rtol=1e-9, atol=1e-9)
        values = m.reconstruct(coords[4])
        expect = m.mean + m.basis[:, 0, :] @ coords[4].reshape(6, 3)
        np.testing.assert_allclose(values.reshape(300, 3), expect, rtol=1e-9, atol=1e-9)
        self.assertFalse(self.model.info["shared_channels"])

    def test_runtime_is_the_papers_arithmetic(self):
        # b = P (k - mean_K); x = mean + B b; key error = RMS over keys of the Euclidean key residual
        # (the default measure), or the largest of them (key_error="largest").
        m, f = self.model, self.frames
        keys = f[:, m.key_points]                                       # (F, K, C)
        coords = m.project(keys)
        expect = (keys - m.mean[m.key_points]).reshape(len(f), -1) @ m.projector.T
        np.testing.assert_allclose(coords, expect, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(m.project(keys[7]), coords[7], rtol=0, atol=0)
        full = m.reconstruct(coords)
        np.testing.assert_allclose(full, m.mean + np.einsum("ncm,fm->fnc", m.basis, coords), atol=1e-9)
        some = np.array([5, 0, 299, 17])
        np.testing.assert_allclose(m.reconstruct(coords[3], points=some), full[3][some], rtol=0, atol=1e-12)
        # A model with a tolerance predicts its point error, T * min(rms / eps_rms, loo / eps_loo):
        # the key RMS and the leave-one-out error (below) each over its calibrated threshold.
        residual = keys - full[:, m.key_points]
        rms = np.sqrt((np.linalg.norm(residual, axis=2) ** 2).mean(axis=1))
        bk = m.basis[m.key_points].reshape(-1, m.basis_size)            # (K*C, M)
        h = np.einsum("jm,mj->j", bk, m.projector)
        loo = np.linalg.norm((residual.reshape(len(f), -1) / (1 - h)).reshape(len(f), -1, 3), axis=2).max(axis=1)
        self.assertEqual(m.info["key_error"], "predicted")
        parts = m.info["key_error_parts_eps"]
        predicted = m.info["tolerance"] * np.minimum(rms / parts["rms"], loo / parts["loo"])
        np.testing.assert_allclose(m.key_error(keys), predicted, rtol=1e-9)
        self.assertEqual(m.info["eps_min"], m.info["tolerance"])
        self.assertIsInstance(m.key_error(keys[0]), float)
        self.assertAlmostEqual(m.key_error(keys[0], coords[0]), predicted[0], places=12)
        # key_error="rms": the paper's RMS over the keys (the default without a tolerance).
        p = pmsc.train(f, max_keys=30, seed=3)
        self.assertEqual(p.info["key_error"], "rms")
        pk = f[:, p.key_points]
        pres = pk - p.reconstruct(p.project(pk))[:, p.key_points]
        np.testing.assert_allclose(p.key_error(pk), np.sqrt((np.linalg.norm(pres, axis=2) ** 2).mean(axis=1)),
                                   rtol=1e-9)
        with self.assertRaises(ValueError):
            pmsc.train(f, max_keys=30, key_error="predicted")  # nothing to predict without a tolerance
        r = pmsc.train(f, max_keys=30, seed=3, key_error="largest")
        rk = f[:, r.key_points]
        res = rk - r.reconstruct(r.project(rk))[:, r.key_points]
        largest = np.linalg.norm(res, axis=2).max(axis=1)
        np.testing.assert_allclose(r.key_error(rk), largest, rtol=1e-9)
        self.assertEqual(r.info["key_error"], "largest")
        # key_error="loo": each key row's residual over 1 - its leverage (the hat matrix's diagonal).
        o = pmsc.train(f, max_keys=30, seed=3, key_error="loo")
        ok = f[:, o.key_points]
        bk = o.basis[o.key_points].reshape(-1, o.basis_size)            # (K*C, M)
        h = np.einsum("jm,mj->j", bk, o.projector)
        res = (ok - o.reconstruct(o.project(ok))[:, o.key_points]).reshape(len(f), -1) / (1 - h)
        loo = np.linalg.norm(res.reshape(len(f), -1, 3), axis=2).max(axis=1)
        np.testing.assert_allclose(o.key_error(ok), loo, rtol=1e-9)
        self.assertEqual(o.info["key_error"], "loo")
        with self.assertRaises(pmsc.InputError):
            pmsc.train(f, max_keys=30, key_error="median")

    def test_float32_array_and_shots(self):
        a = pmsc.train(self.frames.astype(np.float32), max_keys=30, seed=3)
        self.assertEqual(a.key_count, 30)
        halves = pmsc.train([self.frames[:40], self.frames[40:]], max_keys=30, tolerance=0.05, seed=3)
        self.assertEqual(halves.to_bytes(), self.model.to_bytes())   # shots concatenate in order

    def test_save_load_bytes_pickle(self):
        path = self.path("m.pmsc")
        self.model.save(path)
        loaded = pmsc.Model.load(path)
        with open(path, "rb") as f:
            self.assertEqual(f.read(), self.model.to_bytes())
        self.assertEqual(loaded.to_bytes(), self.model.to_bytes())
        self.assertEqual(pickle.loads(pickle.dumps(self.model)).to_bytes(), self.model.to_bytes())
        self.assertEqual(pmsc.Model.from_bytes(self.model.to_bytes()).key_count, 30)

    def test_same_model_bytes_as_the_command_line(self):
        # A float64 array is trained from in place (no FrameSet copy): same bytes as `pmsc train`.
        self.require_cli()
        npy = self.path("train.npy")
        np.save(npy, self.frames)
        run_cli("train", "--frames", npy, "--out", self.path("cli.pmsc"), "--max-keys", 30, "--tolerance", 0.05,
                "--seed", 3, "--quiet")
        with open(self.path("cli.pmsc"), "rb") as f:
            cli = f.read()
        self.assertEqual(self.model.to_bytes(), cli)
        self.assertEqual(pmsc.train(npy, max_keys=30, tolerance=0.05, seed=3).to_bytes(), cli)

    def test_clamp_is_the_command_lines_no_clamp(self):
        # Frames that are never negative give a model clamped at 0 unless clamp=False (--no-clamp).
        self.require_cli()
        npy = self.path("light.npy")
        np.save(npy, self.frames - self.frames.min())
        clamped = pmsc.train(npy, max_keys=30, seed=3)
        self.assertTrue(clamped.info["non_negative"])
        run_cli("train", "--frames", npy, "--out", self.path("linear.pmsc"), "--max-keys", 30, "--seed", 3,
                "--no-clamp", "--quiet")
        with open(self.path("linear.pmsc"), "rb") as f:
            linear = f.read()
        self.assertEqual(pmsc.train(npy, max_keys=30, seed=3, clamp=False).to_bytes(), linear)
        self.assertFalse(pmsc.Model.from_bytes(linear).info["non_negative"])

    def test_positions_give_the_command_lines_sentinels(self):
        # positions= is --positions: an array or a .npy path, the same model bytes as `pmsc train`.
        self.require_cli()
        npy, table = self.path("train.npy"), self.path("positions.npy")
        np.save(npy, self.frames)
        positions = np.random.default_rng(5).random((300, 3))
        np.save(table, positions)
        run_cli("train", "--frames", npy, "--out", self.path("cli.pmsc"), "--max-keys", 30, "--tolerance", 0.05,
                "--seed", 3, "--positions", table, "--quiet")
        with open(self.path("cli.pmsc"), "rb") as f:
            cli = f.read()
        from_array = pmsc.train(self.frames, max_keys=30, tolerance=0.05, seed=3, positions=positions)
        self.assertEqual(from_array.to_bytes(), cli)
        self.assertEqual(pmsc.train(npy, max_keys=30, tolerance=0.05, seed=3, positions=table).to_bytes(), cli)
        self.assertGreater(from_array.info["sentinels"], 0)
        # sentinel_points: the points a hit computes beside its keys, farthest-point samples of the
        # positions (the second is the non-key point farthest from the first), none of them a key.
        s = from_array.sentinel_points
        self.assertEqual(s.dtype, np.int64)
        self.assertEqual(len(s), from_array.info["sentinels"])
        self.assertEqual(len(set(s.tolist())), len(s))
        self.assertFalse(set(s.tolist()) & set(from_array.key_points.tolist()))
        others = np.setdiff1d(np.arange(300), from_array.key_points)
        far = others[np.argmax(np.linalg.norm(positions[others] - positions[s[0]], axis=1))]
        self.assertEqual(s[1], far)
        self.assertEqual(len(pmsc.train(self.frames, max_keys=30, tolerance=0.05, sentinels=0).sentinel_points), 0)
        with self.assertRaisesRegex(pmsc.InputError, "expected 300 rows"):
            pmsc.train(self.frames, max_keys=30, tolerance=0.05, positions=positions[:299])
        with self.assertRaisesRegex(pmsc.InputError, r"positions must be an array \(N, 3\)"):
            pmsc.train(self.frames, max_keys=30, tolerance=0.05, positions=positions.reshape(-1))

    def test_learn_gives_the_command_lines_model_bytes(self):
        # pmsc.learn is `pmsc learn` (app/Learn.h): the same update, the same bytes, from an array or a path.
        self.require_cli()
        first, second = synthetic_frames(seed=4)[:40], synthetic_frames(seed=4, novel=20)[40:]
        model = pmsc.train(first, max_keys=30, tolerance=0.05, seed=3)
        model.save(self.path("day1.pmsc"))
        np.save(self.path("new.npy"), second)
        run_cli("learn", "--model", self.path("day1.pmsc"), "--frames", self.path("new.npy"), "--out",
                self.path("day2.pmsc"), "--quiet")
        with open(self.path("day2.pmsc"), "rb") as f:
            cli = f.read()
        learned = pmsc.learn(model, second)
        self.assertEqual(learned.to_bytes(), cli)
        self.assertEqual(pmsc.learn(model, self.path("new.npy")).to_bytes(), cli)
        self.assertEqual(learned.train_frames, 80)
        self.assertEqual(learned.training_report["new_frames"], 40)

    def test_learn_takes_the_positions_the_model_was_trained_with(self):
        # positions= is learn's --positions: the sentinels chosen again from them, the same bytes.
        self.require_cli()
        first, second = synthetic_frames(seed=4)[:40], synthetic_frames(seed=4, novel=20)[40:]
        positions = np.random.default_rng(5).random((first.shape[1], 3))
        table = self.path("positions.npy")
        np.save(table, positions)
        model = pmsc.train(first, max_keys=30, tolerance=0.05, seed=3, positions=positions)
        model.save(self.path("day1.pmsc"))
        np.save(self.path("new.npy"), second)
        run_cli("learn", "--model", self.path("day1.pmsc"), "--frames", self.path("new.npy"), "--out",
                self.path("day2.pmsc"), "--positions", table, "--quiet")
        with open(self.path("day2.pmsc"), "rb") as f:
            cli = f.read()
        learned = pmsc.learn(model, second, positions=positions)
        self.assertEqual(learned.to_bytes(), cli)
        self.assertEqual(pmsc.learn(model, second, positions=table).to_bytes(), cli)
        self.assertFalse(any("--positions" in w for w in learned.training_report["warnings"]))
        self.assertTrue(any("--positions" in w for w in pmsc.learn(model, second).training_report["warnings"]))
        with self.assertRaisesRegex(pmsc.InputError, "learn: positions"):
            pmsc.learn(model, second, positions=positions[:-1])

    def test_learn_keeps_regions_unless_told_as_the_command_line(self):
        # regions=False is learn's --no-regions; by default a model's regions are kept, byte for byte.
        self.require_cli()
        first, second = synthetic_frames(seed=4)[:40], synthetic_frames(seed=4, novel=20)[40:]
        model = pmsc.train(first, max_keys=30, tolerance=0.05, seed=3, regions=3)
        model.save(self.path("day1.pmsc"))
        np.save(self.path("new.npy"), second)
        for flag, name in (([], "kept.pmsc"), (["--no-regions"], "dropped.pmsc")):
            run_cli("learn", "--model", self.path("day1.pmsc"), "--frames", self.path("new.npy"), "--out",
                    self.path(name), "--quiet", *flag)
        with open(self.path("kept.pmsc"), "rb") as f:
            self.assertEqual(pmsc.learn(model, second).to_bytes(), f.read())
        with open(self.path("dropped.pmsc"), "rb") as f:
            self.assertEqual(pmsc.learn(model, second, regions=False).to_bytes(), f.read())
        self.assertIn("region_keys", pmsc.learn(model, second).training_report)

    def test_regions_by_default_as_the_command_line(self):
        # Local motion on a surface (each of 24 bumps moves a few percent of 2,025 points): `pmsc
        # train --tolerance` learns regions without being told; pmsc.train does the same, byte for byte.
        self.require_cli()
        rng = np.random.default_rng(5)
        g = np.linspace(0.0, 10.0, 45)
        xs, ys = np.meshgrid(g, g)
        rest = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
        centres = rng.uniform(1.0, 9.0, size=(24, 2))
        bumps = np.exp(-((rest[None, :, 0] - centres[:, None, 0]) ** 2 + (rest[None, :, 1] - centres[:, None, 1]) ** 2) / 0.3)
        weights = rng.uniform(-1.0, 1.0, size=(240, 24)) * (rng.uniform(size=(240, 24)) < 0.25)
        frames = np.repeat(rest[None], 240, axis=0)
        frames[:, :, 2] = weights @ bumps
        npy = self.path("local.npy")
        np.save(npy, frames)
        run_cli("train", "--frames", npy, "--out", self.path("local.pmsc"), "--tolerance", 0.05, "--seed", 3, "--quiet")
        with open(self.path("local.pmsc"), "rb") as f:
            cli = f.read()
        model = pmsc.train(npy, tolerance=0.05, seed=3)
        self.assertGreater(model.info["regions"], 0)
        self.assertEqual(model.to_bytes(), cli)
        self.assertEqual(pmsc.train(npy, tolerance=0.05, seed=3, regions=0).info["regions"], 0)
        with self.assertRaises(pmsc.InputError):
            pmsc.train(npy, tolerance=0.05, regions="some")

    def test_progress_can_cancel(self):
        stages = []
        m = pmsc.train(self.frames, max_keys=10, progress=lambda s, d, t: stages.append(s))
        self.assertTrue(stages)
        self.assertEqual(m.key_count, 10)
        with self.assertRaises(pmsc.Cancelled) as e:
            pmsc.train(self.frames, max_keys=10, progress=lambda s, d, t: False)
        self.assertIn("training cancelled", str(e.exception))
        with self.assertRaises(ZeroDivisionError):                     # the hook's own error, unchanged
            pmsc.train(self.frames, max_keys=10, progress=lambda s, d, t: 1 / 0)


if __name__ == "__main__":
    unittest.main()
