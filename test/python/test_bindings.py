"""hpds.downsample against the C++ one-call API (hpds::downsample, run by downsample_dump) on real and synthetic
frames, bit for bit; configs as dicts and YAML files; errors as Python exceptions naming the key."""
import math
import os
import unittest
import warnings

import numpy as np

import hpds
import support

NORMALS = {"output": {"spacing": 0.2}, "normals": {"enabled": True}}


def dump_yaml(case, config, name):
    path = case.path(name)
    with open(path, "w") as f:
        f.write(hpds.config.to_yaml(config))
    return path


class MatchesTheCppApi(support.ScratchCase):
    def setUp(self):
        super().setUp()
        support.require_tools(self)

    def assert_same_samples(self, ours, cpp):
        self.assertEqual(sorted(ours), sorted(cpp))
        self.assertEqual(ours["index"].dtype, np.uint32)
        self.assertEqual(ours["level"].dtype, np.uint8)
        np.testing.assert_array_equal(ours["index"], cpp["index"])
        np.testing.assert_array_equal(ours["level"], cpp["level"])
        if "normal" in cpp:
            self.assertEqual(ours["normal"].shape, (len(ours["index"]), 3))
            # Bit for bit, NaN (no normal) where the C++ API has NaN.
            np.testing.assert_array_equal(ours["normal"].view(np.uint32), cpp["normal"].view(np.uint32))
            np.testing.assert_array_equal(ours["curvature"].view(np.uint32), cpp["curvature"].view(np.uint32))

    def check_file(self, cloud_path, config):
        points = hpds.read_points(cloud_path)
        config_path = dump_yaml(self, config, "config.yaml") if config is not None else "-"
        support.run([support.DOWNSAMPLE_DUMP, cloud_path, config_path, self.path("cpp.bin")])
        cpp = support.read_dump(self.path("cpp.bin"))
        self.assertGreater(len(cpp["index"]), 100)
        ours = hpds.downsample(points, config)
        self.assert_same_samples(ours, cpp)
        # float32 input, a YAML path instead of the dict: the same samples.
        again = hpds.downsample(points.astype(np.float32), config_path if config is not None else None)
        self.assert_same_samples(again, cpp)
        return points, ours

    def test_real_frames(self):
        frames = [f for f in support.shared_frames() if os.path.basename(f) in ("hdl32_a.pcd", "velodyne_vlp16.pcd")]
        if not frames:
            self.skipTest("../shared/data/lidar is absent: real-frame test skipped (CI has it; clones do not)")
        for frame in frames:
            with self.subTest(frame=os.path.basename(frame)):
                self.check_file(frame, {"output": {"spacing": 0.3}})
                points, ours = self.check_file(frame, NORMALS)
                self.assertTrue(np.isfinite(ours["normal"]).any())

    def test_synthetic_lidar_frame(self):
        support.run([support.CLI, "synth", "-o", self.path("synth"), "--frames", "1", "--beams", "16",
                     "--azimuth-steps", "720", "--format", "pcd"])
        frame = self.path("synth/frame_000000.pcd")
        self.check_file(frame, None)
        self.check_file(frame, NORMALS)
        self.check_file(frame, {"order": {"type": "sphericity"}, "output": {"level": 3}})

    def test_covariances_are_gicp_planes_or_the_identity(self):
        support.run([support.CLI, "synth", "-o", self.path("synth"), "--frames", "1", "--beams", "16",
                     "--azimuth-steps", "720", "--format", "pcd"])
        points = hpds.read_points(self.path("synth/frame_000000.pcd"))
        self.assertNotIn("covariance", hpds.downsample(points, NORMALS))
        identities = {}
        # covariance_k 0: the plane is the output normal's; the default: the plane of the 30 nearest samples.
        for k in (0, None):
            normals = {"enabled": True, "covariances": True}
            if k is not None:
                normals["covariance_k"] = k
            s = hpds.downsample(points, {"output": {"spacing": 0.2}, "normals": normals})
            n = len(s["index"])
            self.assertEqual(s["covariance"].shape, (n, 3, 3))
            self.assertEqual(s["covariance"].dtype, np.float32)
            valid = np.isfinite(s["normal"]).all(axis=1)
            # No NaN for GICP to choke on: the identity where there is no normal.
            self.assertFalse(np.isnan(s["covariance"]).any())
            self.assertTrue((s["covariance"][~valid] == np.eye(3, dtype=np.float32)).all())
            self.assertGreater((~valid).sum(), 0)
            cov, normal = s["covariance"][valid].astype(np.float64), s["normal"][valid].astype(np.float64)
            np.testing.assert_allclose(cov, np.transpose(cov, (0, 2, 1)))
            identity = np.all(np.isclose(cov, np.eye(3)), axis=(1, 2))  # a neighbourhood on one scan line
            identities[k] = identity
            planes = ~identity
            self.assertGreater(planes.sum(), n // 2)
            # GICP's plane: eigenvalues (0.001, 1, 1).
            np.testing.assert_allclose(np.linalg.eigvalsh(cov[planes]), np.tile([0.001, 1.0, 1.0], (planes.sum(), 1)),
                                       atol=1e-5)
            along = np.einsum("nij,nj->ni", cov[planes], normal[planes])
            on_normal = np.isclose(along, 0.001 * normal[planes], atol=1e-5).all(axis=1)
            if k == 0:
                self.assertTrue(on_normal.all())
            else:
                self.assertGreater((~on_normal).sum(), 20)  # other planes than the output normals'
        # Which samples get a plane is the output normal's neighbourhood's to say, whatever k.
        np.testing.assert_array_equal(identities[0], identities[None])

    def test_synthetic_planes_from_numpy(self):
        rng = np.random.default_rng(7)
        n = 20000
        u, v = rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)
        xyz = np.stack([u, v, 0.02 * rng.standard_normal(n) - 1.5], axis=1)
        xyz[: n // 2, 2] = u[: n // 2] * 0.3 + 4.0  # a second, tilted plane
        xyz[::97] = 0.0  # no-returns, skipped by both
        support.write_kitti_bin(self.path("planes.bin"), xyz)
        self.check_file(self.path("planes.bin"), NORMALS)


class Arguments(support.ScratchCase):
    def setUp(self):
        super().setUp()
        rng = np.random.default_rng(3)
        self.points = rng.uniform(-8, 8, (5000, 3)).astype(np.float32)

    def test_defaults_and_empty_dict_agree(self):
        a = hpds.downsample(self.points)
        b = hpds.downsample(self.points, {})
        np.testing.assert_array_equal(a["index"], b["index"])
        # The shipped defaults: samples at least 0.1 m apart, with normals.
        self.assertEqual(sorted(a), ["curvature", "index", "level", "normal"])
        self.assertEqual(a["normal"].shape, (len(a["index"]), 3))
        # 5000 points in a 16 m cube lie about 1 m apart: at 0.1 m nearly all are kept.
        self.assertGreater(len(a["index"]), 4000)
        self.assertTrue((a["index"] < len(self.points)).all())

    def test_strided_and_float64_views_give_the_same_samples(self):
        wide = np.zeros((len(self.points), 6), np.float64)
        wide[:, ::2] = self.points
        strided = wide[:, ::2]
        self.assertFalse(strided.flags["C_CONTIGUOUS"])
        a = hpds.downsample(self.points, {"output": {"level": 4}})
        b = hpds.downsample(strided, {"output": {"level": 4}})
        np.testing.assert_array_equal(a["index"], b["index"])
        np.testing.assert_array_equal(a["level"], b["level"])

    def test_georeferenced_float64_keeps_the_guarantees(self):
        # A UTM-like cloud (easting 5e5, northing 4e6): float32 rounds it by up to 0.25 m, more than the 0.1 m
        # radius. float64 is sampled at full precision: every two samples are at least r apart and every point is
        # within 2 r of one, on the float64 positions; with an offset of whole level-0 cells the samples are those
        # of the cloud at the origin; normals are those of the cloud at the origin too.
        rng = np.random.default_rng(12)
        n = 6000
        local = np.stack([rng.uniform(-6, 6, n), rng.uniform(-6, 6, n), 0.01 * rng.standard_normal(n) - 1.5], axis=1)
        config = {"output": {"spacing": 0.1}}
        cell = hpds.load_config(config)["hierarchy"]["cell_size"]
        if cell == 0:  # derived from the spacing: 2 S / sqrt(3) * 2^5 for S = 0.1 (config/hpds.yaml)
            cell = 2 * 0.1 / np.sqrt(3) * 32
        offset = np.round(np.array([5.0e5, 4.0e6, 30.0]) / cell) * cell
        geo = local + offset
        s = hpds.downsample(geo, config)
        pts = geo[s["index"]]
        d2 = ((pts[:, None, :] - pts[None, :, :]) ** 2).sum(axis=2)
        np.fill_diagonal(d2, np.inf)
        self.assertGreaterEqual(np.sqrt(d2.min()), 0.1 * (1 - 1e-6))
        cover = ((geo[:, None, :] - pts[None, :, :]) ** 2).sum(axis=2).min(axis=1)
        self.assertLessEqual(np.sqrt(cover.max()), 0.2 * (1 + 1e-6))
        at_origin = hpds.downsample(local, config, viewpoint=(0.0, 0.0, 0.0))
        shifted_view = hpds.downsample(geo, config, viewpoint=tuple(offset))
        np.testing.assert_array_equal(shifted_view["index"], at_origin["index"])
        valid = np.isfinite(at_origin["normal"][:, 0])
        self.assertGreater(valid.mean(), 0.95)
        np.testing.assert_allclose(shifted_view["normal"][valid], at_origin["normal"][valid], atol=1e-4)
        # The same with range limits, and with a no-return (0,0,0) or a stray point near the origin first: the
        # guarantees do not depend on where the first rows lie (they chose a local origin once, and a leading
        # (0,0,0) left the cloud in float32 at 4e6 m: samples 8 mm apart).
        import warnings
        for first, extra in ((None, {"input": {"max_range": 1.0e7}}), ((0.0, 0.0, 0.0), {}), ((1.0, 1.0, 1.0), {})):
            cloud = geo if first is None else np.vstack([np.array([first]), geo])
            # Without a point near it, the origin is no sensor position: said (below), so given here.
            viewpoint = tuple(offset) if first is None else None
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                got = hpds.downsample(cloud, dict(config, **extra), viewpoint=viewpoint)
            pts = cloud[got["index"]]
            far = pts[np.abs(pts).max(axis=1) > 1e3]
            d2 = ((far[:, None, :] - far[None, :, :]) ** 2).sum(axis=2)
            np.fill_diagonal(d2, np.inf)
            self.assertGreaterEqual(np.sqrt(d2.min()), 0.1 * (1 - 1e-6), first)
            self.assertGreater(len(far), 0.9 * len(s["index"]), first)

    def test_skipped_points_never_appear(self):
        pts = self.points.copy()
        pts[::5] = np.nan
        pts[1::5] = 0.0
        s = hpds.downsample(pts)
        self.assertTrue((s["index"] % 5 >= 2).all())
        self.assertIsInstance(s, dict)
        self.assertEqual(s.skipped["invalid"], len(pts[::5]))
        self.assertEqual(s.skipped["zero"], len(pts[1::5]))
        self.assertEqual(s.skipped["out_of_range"], 0)

    def test_the_resolution_run_at_is_given_and_holds(self):
        s = hpds.downsample(self.points, {"output": {"spacing": 0.3}, "normals": {"enabled": False}})
        r = s.resolution
        # The derived cell: r_L is the spacing, r_D = sqrt(3)/2 * cell_size / 2^D.
        self.assertAlmostEqual(r["radius"], 0.3, places=12)
        self.assertAlmostEqual(r["radius"], math.sqrt(3) / 2 * r["cell_size"] / 2 ** r["output_level"], places=12)
        self.assertEqual(s["level"].max(), r["output_level"])
        self.assertEqual(s.copy().resolution, r)
        self.assertIsNot(s.copy().resolution, r)

    def test_points_beyond_the_key_range_are_counted_and_warned(self):
        # Found: 2e7 m coordinates left the result without a word.
        pts = np.array([[1.0, 2.0, 3.0], [2e7, 0.0, 0.0], [3.0, 2.0, 1.0], [0.0, -2e7, 5.0]])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            s = hpds.downsample(pts)
        self.assertEqual(s.skipped["out_of_range"], 2)
        self.assertEqual(sorted(s["index"].tolist()), [0, 2])
        self.assertEqual(len(caught), 1)
        self.assertIs(caught[0].category, RuntimeWarning)
        self.assertIn("2 points lie beyond the exact key range", str(caught[0].message))
        # What helps at the defaults (a derived cell): fewer levels below the output, not a coarser spacing.
        self.assertIn("reach 1.54981e+07 m", str(caught[0].message))
        self.assertIn("lower hierarchy.max_depth toward the output level 5", str(caught[0].message))
        self.assertNotIn("output.spacing", str(caught[0].message))
        with warnings.catch_warnings(record=True) as shallow:
            warnings.simplefilter("always")
            s = hpds.downsample(pts, {"hierarchy": {"max_depth": 5}})
        self.assertEqual(s.skipped["out_of_range"], 0)
        self.assertEqual(shallow, [])
        with warnings.catch_warnings(record=True) as quiet:
            warnings.simplefilter("always")
            hpds.downsample(pts[[0, 2]])
        self.assertEqual(quiet, [])

    def test_samples_a_map_mode_cap_gives_up_are_counted_and_warned(self):
        # Found in a user trial: map mode over more samples than map.max_samples returned the capped map without a
        # word (the CLI counts and warns).
        config = {"mode": "map", "normals": {"enabled": False}}
        with warnings.catch_warnings(record=True) as quiet:
            warnings.simplefilter("always")
            full = hpds.downsample(self.points, config)
        self.assertEqual(quiet, [])
        self.assertEqual(full.skipped["evicted"], 0)
        capped_config = dict(config, map={"max_samples": 1000})
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            capped = hpds.downsample(self.points, capped_config)
        self.assertEqual(len(capped["index"]), 1000)
        self.assertEqual(capped.skipped["evicted"], len(full["index"]) - 1000)
        self.assertEqual(len(caught), 1)
        self.assertIs(caught[0].category, RuntimeWarning)
        self.assertIn("gave up %d samples" % capped.skipped["evicted"], str(caught[0].message))
        self.assertIn("map.max_samples", str(caught[0].message))
        # The farthest from the sensor went.
        kept = np.linalg.norm(self.points[capped["index"]], axis=1).max()
        gone = np.setdiff1d(full["index"], capped["index"])
        self.assertLessEqual(kept, np.linalg.norm(self.points[gone], axis=1).min())
        # A copy keeps the counts.
        c = capped.copy()
        self.assertIsInstance(c, hpds.Samples)
        self.assertEqual(c.skipped, capped.skipped)
        self.assertIsNot(c.skipped, capped.skipped)

    def test_float32_points_rounded_beyond_the_radius_are_warned(self):
        # Found in a user trial: a float32 cloud in UTM coordinates (5e6 m: float32 steps of 0.5 m) lost a third of
        # its samples to the rounding without a word; the CLI warns for such a file.
        utm = self.points.astype(np.float64) + np.array([5.0e5, 5.0e6, 0.0])
        east = (5.0e5, 5.0e6, 0.0)  # the sensor, where the points are: no far-viewpoint warning
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            hpds.downsample(utm.astype(np.float32), {"normals": {"enabled": False}}, viewpoint=east)
        self.assertEqual(len(caught), 1)
        self.assertIs(caught[0].category, RuntimeWarning)
        self.assertIn("the input's own float32 x y z round positions by up to 0.29", str(caught[0].message))
        self.assertIn("local frame", str(caught[0].message))
        # float64, and float32 near the origin, say nothing.
        for quiet_points, vp in ((utm, east), (self.points, None)):
            with warnings.catch_warnings(record=True) as quiet:
                warnings.simplefilter("always")
                hpds.downsample(quiet_points, {"normals": {"enabled": False}}, viewpoint=vp)
            self.assertEqual(quiet, [])
        # The threshold is 1 % of the output radius: 0.5 mm at a 5 cm spacing is reached at about 8400 m.
        for x, warned in ((8000.0, False), (9000.0, True)):
            with warnings.catch_warnings(record=True) as w:
                warnings.simplefilter("always")
                hpds.downsample((self.points + np.float32(x)).astype(np.float32),
                                {"output": {"spacing": 0.05}, "normals": {"enabled": False}}, viewpoint=(x, x, x))
            self.assertEqual(len(w), int(warned), x)

    def test_a_viewpoint_far_from_every_point_is_warned(self):
        # Found in a trial: world (UTM) points without the sensor's position gave 49 % of the normals flipped
        # against the sensor's, without the warning `hpds sample` gives for the same cloud.
        far = self.points.astype(np.float64) + np.array([5.0e5, 5.4e6, 0.0])
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            hpds.downsample(far)
        self.assertEqual(len(caught), 1)
        self.assertIs(caught[0].category, RuntimeWarning)
        self.assertIn("m from the viewpoint (0, 0, 0)", str(caught[0].message))
        self.assertIn("pass the sensor's position as viewpoint=(x, y, z)", str(caught[0].message))
        # Given the sensor's position, or with the points in the sensor's frame, nothing; NaN points do not count.
        with_nan = np.vstack([np.full((3, 3), np.nan), self.points.astype(np.float64)])
        for points, vp in ((far, (5.0e5, 5.4e6, 0.0)), (with_nan, None)):
            with warnings.catch_warnings(record=True) as quiet:
                warnings.simplefilter("always")
                hpds.downsample(points, viewpoint=vp)
            self.assertEqual(quiet, [])

    def test_ctrl_c_stops_a_long_call(self):
        # Found in a user trial: a call of seconds on millions of points took Ctrl-C only once it had finished (19 s
        # on 3 M points). The call now runs beside a thread that lets Python's handlers run and stops the work when
        # one raises. Measured against the same call without a signal, in this run.
        import signal
        import threading
        import time
        rng = np.random.default_rng(5)
        n = 1_000_000
        cloud = np.c_[rng.uniform(-40, 40, n), rng.uniform(-40, 40, n), 0.01 * rng.standard_normal(n) - 1.5]
        t0 = time.monotonic()
        whole = hpds.downsample(cloud)
        full = time.monotonic() - t0
        self.assertGreater(len(whole["index"]), 100000)
        self.assertIs(signal.getsignal(signal.SIGINT), signal.default_int_handler)
        timer = threading.Timer(0.05 * full, lambda: os.kill(os.getpid(), signal.SIGINT))
        t0 = time.monotonic()
        timer.start()
        try:
            with self.assertRaises(KeyboardInterrupt):
                hpds.downsample(cloud)
                time.sleep(10 * full)  # not stopped inside the call: the signal lands here, and the check below fails
        finally:
            timer.cancel()
        self.assertLess(time.monotonic() - t0, 0.6 * full, full)
        # The next call is not affected.
        again = hpds.downsample(cloud)
        np.testing.assert_array_equal(again["index"], whole["index"])

    def test_version(self):
        self.assertRegex(hpds.__version__, r"^\d+\.\d+\.\d+$")

    def test_empty_input(self):
        s = hpds.downsample(np.zeros((0, 3), np.float32), NORMALS)
        self.assertEqual(len(s["index"]), 0)
        self.assertEqual(s["normal"].shape, (0, 3))

    def test_numpy_scalars_in_the_dict(self):
        a = hpds.downsample(self.points, {"hierarchy": {"cell_size": np.float64(2.0), "max_depth": np.int64(5)}})
        b = hpds.downsample(self.points, {"hierarchy": {"cell_size": 2.0, "max_depth": 5}})
        np.testing.assert_array_equal(a["index"], b["index"])

    def test_config_errors_name_the_key(self):
        cases = [
            ({"hierarchy": {"cell_size": -1.0}}, "hierarchy.cell_size"),
            ({"hierarchy": {"max_depth": 40}}, "hierarchy.max_depth"),
            ({"hierarchy": {"cell_sise": 1.0}}, "hierarchy.cell_sise"),
            ({"order": {"seed": "5"}}, "order.seed"),
            ({"order": {"type": "best"}}, "order.type"),
            ({"normals": {"enabled": 1}}, "normals.enabled"),
            ({"output": {"spacing": float("nan")}}, "output.spacing"),
            ({"mode": "tiles"}, "mode"),
            ({"hierarchy": 4.0}, "hierarchy"),
        ]
        for config, key in cases:
            with self.subTest(key=key):
                with self.assertRaises(ValueError) as e:
                    hpds.downsample(self.points, config)
                self.assertIn(key, str(e.exception))

    def test_config_file_errors(self):
        with self.assertRaises(FileNotFoundError):
            hpds.downsample(self.points, self.path("missing.yaml"))
        bad = self.path("bad.yaml")
        with open(bad, "w") as f:
            f.write("hierarchy:\n  max_depth: deep\n")
        with self.assertRaises(ValueError) as e:
            hpds.downsample(self.points, bad)
        self.assertIn("hierarchy.max_depth", str(e.exception))
        # The node's `ros:` section is checked as the node checks the file (hpds sample does), though unused here.
        node_bad = self.path("node_bad.yaml")
        with open(node_bad, "w") as f:
            f.write("ros:\n  queue_size: 0\n")
        with self.assertRaises(ValueError) as e:
            hpds.downsample(self.points, node_bad)
        self.assertIn("ros.queue_size: must be in 1..1000, got 0 (in %s)" % node_bad, str(e.exception))
        with self.assertRaises(TypeError):
            hpds.downsample(self.points, 42)
        with self.assertRaises(TypeError):
            hpds.downsample(self.points, {"hierarchy": {"cell_size": object()}})

    def test_points_errors(self):
        # Each type error says how to get the array asked for.
        with self.assertRaises(TypeError) as e:
            hpds.downsample(self.points.astype(np.int32))
        self.assertIn("astype(numpy.float64)", str(e.exception))
        with self.assertRaises(TypeError) as e:
            hpds.downsample(self.points.tolist())
        self.assertIn("numpy.asarray", str(e.exception))
        flat = np.zeros(4, dtype=[("x", "f4"), ("y", "f4"), ("intensity", "f4")])
        with self.assertRaises(TypeError) as e:
            hpds.downsample(flat)
        self.assertIn("needs fields x, y and z; it has x, y, intensity", str(e.exception))
        ints = np.zeros(4, dtype=[("x", "i4"), ("y", "i4"), ("z", "i4")])
        with self.assertRaises(TypeError) as e:
            hpds.downsample(ints)
        self.assertIn("must be float32 or float64", str(e.exception))

    def test_a_cloud_with_every_field_is_read_and_sampled_as_is(self):
        # Found in a user trial: from Python only x y z could be read, though every sample is an input point with all
        # its fields. read_cloud gives the records; downsample takes them; cloud[index] are the samples, every field.
        support.require_tools(self)
        n = 3000
        rng = np.random.default_rng(8)
        dt = np.dtype({"names": ["x", "y", "z", "intensity", "ring", "time"],
                       "formats": ["<f4", "<f4", "<f4", "<f4", "<u2", "<f8"],
                       "offsets": [0, 4, 8, 16, 20, 24], "itemsize": 32})  # PCL-style padding after z
        cloud = np.zeros(n, dt)
        cloud["x"], cloud["y"] = rng.uniform(-10, 10, n), rng.uniform(-10, 10, n)
        cloud["z"] = -1.5
        cloud["intensity"] = rng.uniform(0, 100, n)
        cloud["ring"] = np.arange(n) % 32
        cloud["time"] = np.arange(n) * 1e-5
        path = self.path("fields.pcd")
        header = ("VERSION .7\nFIELDS x y z _ intensity ring _ time\nSIZE 4 4 4 4 4 2 2 8\nTYPE F F F U F U U F\n"
                  "COUNT 1 1 1 1 1 1 1 1\nWIDTH %d\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA binary\n" % (n, n))
        with open(path, "wb") as f:
            f.write(header.encode())
            f.write(cloud.tobytes())
        read = hpds.read_cloud(path)
        for name in dt.names:
            np.testing.assert_array_equal(read[name], cloud[name], name)
        self.assertEqual(read.dtype["ring"], np.dtype("<u2"))
        s = hpds.downsample(read)
        xyz = hpds.read_points(path)
        np.testing.assert_array_equal(s["index"], hpds.downsample(xyz.astype(np.float32))["index"])
        samples = read[s["index"]]
        np.testing.assert_array_equal(samples["intensity"], cloud["intensity"][s["index"]])
        np.testing.assert_array_equal(samples["time"], cloud["time"][s["index"]])
        # The sampled records are what `hpds sample` writes (its PLY holds the same fields, values and order).
        ply = self.path("fields.ply")
        support.run([support.CLI, "sample", path, "-o", ply])
        written = hpds.ply.read(ply)
        for name in ("x", "y", "z", "intensity", "ring", "time"):
            np.testing.assert_array_equal(written[name], samples[name], name)
        with_vp, vp = hpds.read_cloud(path, return_viewpoint=True)
        self.assertEqual(len(with_vp), n)
        np.testing.assert_array_equal(vp, np.zeros(3))
        with self.assertRaises(ValueError) as e:
            hpds.downsample(self.points[:, :2])
        self.assertIn("(5000, 2)", str(e.exception))
        with self.assertRaises(ValueError):
            hpds.downsample(self.points.reshape(-1))

    def test_float_dtypes_by_kind_not_identity(self):
        # Byte-swapped and metadata-carrying float arrays are floats: the same samples as the native array.
        want = hpds.downsample(self.points)["index"]
        for dtype in (np.dtype(">f8"), np.dtype(">f4"), np.dtype("f8", metadata={"unit": "m"})):
            with self.subTest(dtype=str(dtype)):
                got = hpds.downsample(self.points.astype(dtype))["index"]
                self.assertTrue(np.array_equal(got, want))
        for dtype in (np.float16, np.longdouble):
            with self.subTest(dtype=str(dtype)):
                with self.assertRaises(TypeError) as e:
                    hpds.downsample(self.points.astype(dtype))
                self.assertIn("float32 or float64", str(e.exception))

    def test_an_array_where_one_value_belongs_names_the_key(self):
        for value in (np.array([0.3, 0.4]), [0.3, 0.4], np.array([[0.3]])):
            with self.subTest(value=repr(value)):
                with self.assertRaises((ValueError, TypeError)) as e:
                    hpds.downsample(self.points, {"output": {"spacing": value}})
                self.assertIn("output.spacing", str(e.exception))
        # A one-element NumPy value is a scalar.
        self.assertTrue(np.array_equal(hpds.downsample(self.points, {"output": {"spacing": np.float64(0.3)}})["index"],
                                       hpds.downsample(self.points, {"output": {"spacing": 0.3}})["index"]))

    def test_load_config_is_the_core_defaults_plus_the_overrides(self):
        c = hpds.load_config({"normals": {"enabled": True}, "order": {"seed": 9}})
        self.assertIs(c["normals"]["enabled"], True)
        self.assertEqual(c["order"]["seed"], 9)
        self.assertIsInstance(c["hierarchy"]["cell_size"], float)
        self.assertIsInstance(c["hierarchy"]["max_depth"], int)
        # The dict reads back as the same config.
        self.assertEqual(hpds.load_config(c), c)


class Poses(support.ScratchCase):
    def test_kitti_and_tum_files_give_the_same_matrices(self):
        # A quarter turn about z, then half a turn about x, at a far offset; TUM lists qx qy qz qw after the time.
        kitti = "# sensor to world\n0 -1 0 1000.5 1 0 0 -20 0 0 1 3\n1 0 0 0 0 -1 0 0 0 0 -1 0\n"
        s = np.sqrt(0.5)
        tum = "# timestamp tx ty tz qx qy qz qw\n1.0 1000.5 -20 3 0 0 %r %r\n\n1.1 0 0 0 1 0 0 0\n" % (s, s)
        for name, text in (("p.txt", kitti), ("p.tum", tum)):
            with open(self.path(name), "w") as f:
                f.write(text)
        a, b = hpds.read_poses(self.path("p.txt")), hpds.read_poses(self.path("p.tum"))
        self.assertEqual(a.shape, (2, 4, 4))
        np.testing.assert_allclose(b, a, atol=1e-15)
        with open(self.path("mixed.txt"), "w") as f:
            f.write(kitti + tum)
        with self.assertRaises(RuntimeError) as e:
            hpds.read_poses(self.path("mixed.txt"))
        self.assertIn("one format per file", str(e.exception))

    def test_a_rotation_corrected_beyond_rounding_is_warned_about(self):
        # A row scaled by 1.0003: accepted (within 1e-3), made a true rotation, which moves a point 100 m out by 3 cm.
        for text, warned in (("1 0 0 0 0 1 0 0 0 0 1 0\n", False), ("1 0 0 0 0 1.0003 0 0 0 0 1 0\n", True)):
            with open(self.path("scaled.txt"), "w") as f:
                f.write(text)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                poses = hpds.read_poses(self.path("scaled.txt"))
            np.testing.assert_allclose(poses[0, :3, :3], np.eye(3), atol=1e-15)
            self.assertEqual(len(caught), int(warned), [str(w.message) for w in caught])
            if warned:
                self.assertIn("line 1", str(caught[0].message))
                self.assertIn("by up to 0.03 m", str(caught[0].message))


class Viewpoint(support.ScratchCase):
    """A PCD's VIEWPOINT is where its sensor was: normals face it in hpds sample, and in Python when passed on."""

    def write_ground_pcd(self, viewpoint):
        rng = np.random.default_rng(11)
        n = 6000
        xyz = np.stack([rng.uniform(-6, 6, n), rng.uniform(-6, 6, n), 0.01 * rng.standard_normal(n) - 1.5], axis=1)
        xyz = xyz.astype(np.float32)
        path = self.path("ground.pcd")
        with open(path, "w") as f:
            f.write("VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH %d\nHEIGHT 1\n" % n)
            f.write("VIEWPOINT %r %r %r 1 0 0 0\nPOINTS %d\nDATA ascii\n" % (*viewpoint, n))
            for p in xyz:
                f.write("%r %r %r\n" % tuple(float(v) for v in p))
        return path, xyz

    def test_read_points_returns_the_viewpoint(self):
        path, xyz = self.write_ground_pcd((1.0, -2.0, -10.0))
        points, viewpoint = hpds.read_points(path, return_viewpoint=True)
        np.testing.assert_array_equal(viewpoint, [1.0, -2.0, -10.0])
        np.testing.assert_array_equal(points, xyz.astype(np.float64))
        # The plain call is unchanged: the points alone.
        np.testing.assert_array_equal(hpds.read_points(path), points)
        support.write_kitti_bin(self.path("ground.bin"), xyz)
        np.testing.assert_array_equal(hpds.read_points(self.path("ground.bin"), return_viewpoint=True)[1], [0, 0, 0])

    def test_missing_files_raise_the_os_errors_python_callers_catch(self):
        missing = self.path("no_such_frame.pcd")
        for call in (lambda p: hpds.read_points(p), lambda p: hpds.read_poses(p), lambda p: hpds.load_config(p)):
            with self.assertRaises(FileNotFoundError) as e:
                call(missing)
            self.assertEqual(e.exception.filename, missing)
            with self.assertRaises(IsADirectoryError):
                call(self.path(""))
        # A file that exists but is no point cloud stays the core's error, naming the file.
        garbage = self.path("garbage.pcd")
        with open(garbage, "w") as f:
            f.write("not a point cloud\n")
        with self.assertRaises(RuntimeError) as e:
            hpds.read_points(garbage)
        self.assertIn("garbage.pcd", str(e.exception))

    def test_normals_face_the_viewpoint_as_in_hpds_sample(self):
        support.require_tools(self)
        config = {"output": {"spacing": 0.2}, "normals": {"enabled": True}}
        path, _ = self.write_ground_pcd((0.0, 0.0, -10.0))  # the ground seen from below: normals point down
        points, viewpoint = hpds.read_points(path, return_viewpoint=True)
        ours = hpds.downsample(points, config, viewpoint)
        valid = np.isfinite(ours["normal"]).all(axis=1)
        self.assertGreater(valid.sum(), 100)
        self.assertTrue((ours["normal"][valid, 2] < -0.9).all())
        # Without it they face the origin, above the ground.
        up = hpds.downsample(points, config)
        self.assertTrue((up["normal"][np.isfinite(up["normal"]).all(axis=1), 2] > 0.9).all())
        # The CLI reads VIEWPOINT itself: the same samples and normals, bit for bit.
        support.run([support.CLI, "sample", path, "-o", self.path("cli.ply"), "--spacing", "0.2"])
        cli = hpds.ply.read(self.path("cli.ply"))
        np.testing.assert_array_equal(cli["level"], ours["level"])
        cli_normal = np.stack([cli["normal_x"], cli["normal_y"], cli["normal_z"]], axis=1).astype(np.float32)
        np.testing.assert_array_equal(cli_normal.view(np.uint32), ours["normal"].view(np.uint32))

    def test_a_viewpoint_that_is_not_three_finite_numbers_is_refused(self):
        points = np.random.default_rng(2).uniform(-4, 4, (500, 3))
        for bad in ((0.0, 0.0), (0.0, float("nan"), 0.0), "abc"):
            with self.subTest(viewpoint=bad), self.assertRaises(ValueError):
                hpds.downsample(points, None, bad)


if __name__ == "__main__":
    unittest.main()
