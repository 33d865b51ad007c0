"""python3 -m hpds.map_build on a synthetic drive (`hpds synth`): the merged tiles pass `hpds verify` (no
violation, coverage of every input point), seams lie in dense geometry, a 2-worker LocalCluster writes the same
bytes as one process, a worker killed in the middle of a tile is retried (or, killed every time, stops the build
with the tile named and nothing half-written published), and the build never overwrites an input or an earlier
build."""
import contextlib
import fcntl
import filecmp
import functools
import glob
import io
import json
import logging
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import unittest

import numpy as np

import hpds
import hpds.ply
from hpds import map_build
from hpds.runners import BuildError, DaskRunner, SerialRunner
from hpds.tiled_build import build
import support

TILE = 8.0
CELL = 2.0
SAMPLING = ["--cell-size", str(CELL), "--max-depth", "5", "--level", "4", "--normals"]


def _killing_call(fn, marks, times, watch, *args):
    """Runs fn(*args), but the first `times` runs (counted by files in `marks`) kill their own worker process in the
    middle: as soon as a temporary of the task's output appears (or, at the latest, when the work is done and
    before its result is reported)."""
    n = len(os.listdir(marks))
    if n >= times:
        return fn(*args)
    worker = threading.Thread(target=fn, args=args, daemon=True)
    worker.start()
    seen = False
    while worker.is_alive() and not seen:
        seen = bool(glob.glob(glob.escape(watch) + "*tmp*"))
        time.sleep(0.0005)
    with open(os.path.join(marks, "%d-%d-%s" % (n, os.getpid(), "mid-write" if seen else "after")), "w"):
        pass
    os.kill(os.getpid(), signal.SIGKILL)


class KillWorker:
    """A runner `wrap`: the task with key `key` kills its worker the first `times` times it runs."""

    def __init__(self, key, marks, times, watch):
        self.key, self.marks, self.times, self.watch = key, marks, times, watch

    def __call__(self, task):
        if task.key != self.key:
            return task.fn
        return functools.partial(_killing_call, task.fn, self.marks, self.times, self.watch)


def tile_files(outdir):
    return sorted(os.path.basename(p) for p in glob.glob(os.path.join(outdir, "tile_*.ply")))


class MapBuild(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        if not support.CLI:
            raise unittest.SkipTest("HPDS_CLI not set: run through ctest")
        cls.root = tempfile.mkdtemp(prefix="hpds_map_build_")
        drive = os.path.join(cls.root, "drive")
        support.run([support.CLI, "synth", "-o", drive, "--frames", "6", "--beams", "16", "--azimuth-steps", "900",
                     "--speed", "2.5"])
        cls.frames = sorted(glob.glob(os.path.join(drive, "frame_*.pcd")))
        cls.poses = os.path.join(drive, "poses.txt")
        cls.reference = os.path.join(cls.root, "serial")
        rc = map_build.main(cls.frames + ["--poses", cls.poses, "-o", cls.reference, "--tile-size", str(TILE),
                                          "--workers", "0"] + SAMPLING)
        assert rc == 0, "the serial reference build failed"
        with open(os.path.join(cls.reference, "manifest.json")) as f:
            cls.manifest = json.load(f)
        a = map_build.parse_args(cls.frames + ["--poses", cls.poses, "-o", "x", "--tile-size", str(TILE)] + SAMPLING)
        cls.config_yaml = map_build.resolve_config(a)

    @classmethod
    def tearDownClass(cls):
        shutil.rmtree(cls.root, ignore_errors=True)

    def dask(self):
        """A fresh 2-worker LocalCluster for this test, closed when it ends. Not shared: a test that kills workers
        leaves the cluster to its nannies, and Dask itself (Debian's distributed) can lose a restarted worker for
        good (an assertion in the worker's own close path), which must not fail the next test. A task whose
        workers die twice fails (KilledWorker), and the runner submits it again up to twice more."""
        import dask
        from distributed import Client, LocalCluster

        dask.config.set({"distributed.scheduler.allowed-failures": 1})
        logging.getLogger("distributed").setLevel(logging.CRITICAL)
        cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.CRITICAL)
        self.addCleanup(cluster.close)
        client = Client(cluster)
        self.addCleanup(client.close)
        client.wait_for_workers(2, timeout=120)
        return client

    def out(self, name):
        return os.path.join(self.root, name)

    def assert_same_tiles(self, outdir):
        names = tile_files(self.reference)
        self.assertEqual(tile_files(outdir), names)
        for n in names:
            self.assertTrue(filecmp.cmp(os.path.join(outdir, n), os.path.join(self.reference, n), shallow=False), n)

    def assert_no_temporaries(self, outdir):
        left = [p for p in glob.glob(os.path.join(outdir, "**", "*"), recursive=True) if "tmp" in os.path.basename(p)]
        self.assertEqual(left, [])

    def test_merged_tiles_pass_verify_with_coverage_of_every_input_point(self):
        m = self.manifest
        self.assertGreaterEqual(len(m["tiles"]), 12)
        self.assertEqual(m["config"]["mode"], "map")
        self.assertEqual(m["config"]["hierarchy"]["cell_size"], CELL)
        self.assertEqual(m["output_level"], 4)
        self.assertEqual(tile_files(self.reference), sorted(t["file"] for t in m["tiles"]))
        self.assertFalse(os.path.exists(os.path.join(self.reference, ".hpds_work")))
        cpu = m["run"]["task_cpu_seconds"]
        self.assertGreater(cpu["tiles"], 0.0)
        self.assertGreater(cpu["critical_path"], 0.0)
        self.assertLessEqual(cpu["critical_path"], cpu["bucketing"] + cpu["tiles"] + cpu["outputs"] + 1e-9)
        self.assert_no_temporaries(self.reference)
        merged = self.out("merged.ply")
        hpds.ply.merge([os.path.join(self.reference, t["file"]) for t in m["tiles"]], merged)
        cloud = hpds.ply.read(merged)
        self.assertEqual(len(cloud), m["counts"]["samples_written"])
        self.assertIn("normal_x", cloud.dtype.names)
        # The input, posed as the pipeline does (no-returns at the sensor origin are skipped, as it skips them).
        poses = hpds.read_poses(self.poses)
        posed = []
        for frame, pose in zip(self.frames, poses):
            p = hpds.read_points(frame)
            p = p[np.isfinite(p).all(axis=1) & (p != 0).any(axis=1)]
            posed.append(p @ pose[:3, :3].T + pose[:3, 3])
        posed = np.concatenate(posed)
        self.assertEqual(len(posed), m["counts"]["input_points"] - m["counts"]["skipped_invalid"] -
                         m["counts"]["skipped_zero"])
        xyz = np.zeros(len(posed), [("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
        xyz["x"], xyz["y"], xyz["z"] = posed[:, 0], posed[:, 1], posed[:, 2]
        hpds.ply.write(self.out("input.ply"), xyz)
        # The tiles' header records the sampling, and the merge keeps it: verify needs no --cell-size, and checks
        # coverage down to the recorded output level.
        record = hpds.ply.read_sampling_record(merged)
        self.assertIsNotNone(record)
        self.assertEqual((record[0], record[2]), (CELL, 4))
        rc, text = support.run([support.CLI, "verify", merged, "--input", self.out("input.ply")], check=False)
        self.assertEqual(rc, 0, text)
        self.assertIn("as its header records: level-0 cell", text)
        self.assertIn("OK: no violations", text)
        # The seams cut dense geometry: many samples within r_0 of a tile border, on both of its sides.
        r0 = 0.5 * np.sqrt(3.0) * CELL
        for axis in ("x", "y"):
            off = np.mod(cloud[axis].astype(np.float64), TILE)
            near_low, near_high = (off < r0).sum(), (off > TILE - r0).sum()
            self.assertGreater(min(near_low, near_high), 500, axis)

    def test_two_dask_workers_write_the_same_bytes_as_one_process(self):
        # --workers 2: the command starts (and stops) its own 2-worker LocalCluster; --scheduler joins a running one,
        # started only once the first build is done (four workers on two cores would slow both).
        for name, runner_args in (("dask2", lambda: ["--workers", "2"]),
                                  ("dask_scheduler", lambda: ["--scheduler", self.dask().scheduler.address])):
            where = runner_args()
            with self.subTest(where=where[0]):
                out = self.out(name)
                rc = map_build.main(self.frames + ["--poses", self.poses, "-o", out, "--tile-size", str(TILE),
                                                   "--chunk-frames", "1"] + where + SAMPLING)
                self.assertEqual(rc, 0)
                self.assert_same_tiles(out)
                with open(os.path.join(out, "manifest.json")) as f:
                    m = json.load(f)
                self.assertEqual(m["run"]["workers"], 2)
                self.assertEqual(m["run"]["bucketing_tasks"], len(self.frames))
                for k in ("tiles", "counts", "config", "bounds"):
                    self.assertEqual(m[k], self.manifest[k], k)

    def test_dask_workers_keep_freed_memory_and_other_processes_keep_their_policy(self):
        # Dask's nanny starts workers with MALLOC_TRIM_THRESHOLD_, which made each task map and unmap its scratch
        # (a 1-worker build took 2.8x the time of --workers 0): the tasks set the CLI's malloc policy in workers,
        # and only there. Under a sanitizer its allocator replaces glibc's malloc: the workers must still have asked.
        from hpds import tiled_build

        self.assertFalse(tiled_build.keep_freed_memory_in_workers())
        self.assertFalse(tiled_build._memory_asked)
        self.assertFalse(tiled_build._memory_kept)
        client = self.dask()
        out = self.out("dask_memory")
        build(self.frames, self.poses, out, TILE, self.config_yaml, DaskRunner(client), log=lambda m: None)
        self.assert_same_tiles(out)
        state = client.run(lambda: (__import__("hpds.tiled_build").tiled_build._memory_asked,
                                    __import__("hpds.tiled_build").tiled_build._memory_kept))
        self.assertEqual(len(state), 2)
        expected = (True, tiled_build._hpds.frame_memory_can_be_kept)
        self.assertTrue(all(tuple(v) == expected for v in state.values()), (state, expected))

    def test_a_worker_killed_in_the_middle_of_a_tile_is_retried(self):
        biggest = max(self.manifest["tiles"], key=lambda t: t["points"])
        out, marks = self.out("killed_once"), self.out("marks_once")
        os.makedirs(marks)
        wrap = KillWorker("finish-%d_%d" % (biggest["i"], biggest["j"]), marks, 1,
                          os.path.join(out, biggest["file"]))
        build(self.frames, self.poses, out, TILE, self.config_yaml, DaskRunner(self.dask(), wrap=wrap),
              log=lambda m: None)
        self.assertEqual(len(os.listdir(marks)), 1)  # it did die once
        self.assert_same_tiles(out)
        self.assertTrue(os.path.exists(os.path.join(out, "manifest.json")))
        self.assert_no_temporaries(out)

    def test_a_tile_whose_workers_keep_dying_stops_the_build_with_its_name(self):
        # Tasks queued on the same worker die with the crashing one, and may do so every time they are retried:
        # with no retries at all every such task is a suspect at once, and only a run alone tells them apart.
        tile = [t for t in self.manifest["tiles"] if t["phase"] == 1][0]
        for retries in (0, 2):
            with self.subTest(retries=retries):
                # Debian's Dask can fail to replace a killed worker for good (an assertion in the worker's close
                # path): the runner then stops, saying the cluster has no workers, and the run is repeated on a fresh
                # cluster. What is checked below is only ever the runner's verdict on a cluster that kept its workers.
                for attempt in range(3):
                    out = self.out("killed_always_%d_%d" % (retries, attempt))
                    marks = self.out("marks_always_%d_%d" % (retries, attempt))
                    os.makedirs(marks)
                    wrap = KillWorker("build-%d_%d" % (tile["i"], tile["j"]), marks, 100,
                                      os.path.join(out, ".hpds_work", "tiles",
                                                   "tile_%d_%d.hpdsmap" % (tile["i"], tile["j"])))
                    with self.assertRaises(BuildError) as e:
                        build(self.frames, self.poses, out, TILE, self.config_yaml,
                              DaskRunner(self.dask(), wrap=wrap, retries=retries, no_worker_timeout=30.0),
                              log=lambda m: None)
                    if "has had no workers" not in str(e.exception):
                        break
                self.assertIn("tile (%d, %d)" % (tile["i"], tile["j"]), str(e.exception))
                self.assertIn("died", str(e.exception))
                # Once per submission it died on allowed-failures + 1 = 2 workers, and twice more running alone.
                self.assertEqual(len(os.listdir(marks)), 2 * (retries + 1) + 2, str(e.exception))
                self.assertFalse(os.path.exists(os.path.join(out, "manifest.json")))
                self.assertNotIn(tile["file"], tile_files(out))
                # What was published is complete: every tile file present equals the reference's.
                for n in tile_files(out):
                    self.assertTrue(filecmp.cmp(os.path.join(out, n), os.path.join(self.reference, n),
                                                shallow=False), n)
                self.assertEqual([p for p in os.listdir(out) if "tmp" in p], [])
                self.assertFalse(os.path.exists(os.path.join(out, ".hpds_work")))

    def test_a_cluster_without_workers_stops_the_build_instead_of_waiting(self):
        # Dask keeps tasks in 'no-worker' for ever when every worker is gone; seen when the nannies could not
        # replace killed workers (the build then hung until ctest's timeout).
        from distributed import Client, LocalCluster

        cluster = LocalCluster(n_workers=0, processes=False, dashboard_address=None, silence_logs=logging.CRITICAL)
        self.addCleanup(cluster.close)
        client = Client(cluster)
        self.addCleanup(client.close)
        out = self.out("no_workers")
        start = time.monotonic()
        with self.assertRaises(BuildError) as e:
            build(self.frames, self.poses, out, TILE, self.config_yaml, DaskRunner(client, no_worker_timeout=2.0),
                  log=lambda m: None)
        self.assertIn("the Dask cluster has had no workers for", str(e.exception))
        self.assertIn("run the build again", str(e.exception))
        self.assertLess(time.monotonic() - start, 60.0)
        self.assertFalse(os.path.exists(os.path.join(out, "manifest.json")))
        self.assertEqual(tile_files(out), [])

    def test_never_overwrites_an_input_or_an_earlier_build(self):
        # An earlier build in OUTDIR: refused, nothing touched.
        before = {n: os.path.getmtime(os.path.join(self.reference, n)) for n in os.listdir(self.reference)}
        with self.assertRaises(BuildError) as e:
            build(self.frames, self.poses, self.reference, TILE, self.config_yaml, SerialRunner(), log=lambda m: None)
        self.assertIn("already holds a tiled build", str(e.exception))
        self.assertEqual({n: os.path.getmtime(os.path.join(self.reference, n)) for n in os.listdir(self.reference)},
                         before)
        # An input that has an output's name.
        out = self.out("clash")
        os.makedirs(out)
        shutil.copy(self.frames[0], os.path.join(out, "tile_0_0.ply"))
        with self.assertRaises(BuildError):
            build([os.path.join(out, "tile_0_0.ply")], self.poses, out, TILE, self.config_yaml, SerialRunner(),
                  log=lambda m: None)

    def test_a_folder_is_its_frames_in_name_order_and_a_glob_order_is_warned(self):
        # A trial's map was posed wrong without a word: `map_build frames/*.pcd` with unpadded names gets the shell's
        # text order (f_10 before f_2), and a folder, which `hpds sample` takes in name order, was refused.
        folder = self.out("unpadded")
        os.makedirs(folder)
        for i, f in enumerate(self.frames):
            shutil.copy(f, os.path.join(folder, "f_%d.pcd" % (i * 4)))  # f_0 f_4 f_8 f_12 f_16 f_20
        logs = []
        build([folder], self.poses, self.out("from_folder"), TILE, self.config_yaml, SerialRunner(), log=logs.append)
        self.assert_same_tiles(self.out("from_folder"))
        self.assertTrue(any("6 inputs in name order, 'f_0.pcd' to 'f_20.pcd'" in m for m in logs), logs)
        self.assertFalse(any("warning" in m for m in logs), logs)
        text_order = sorted(glob.glob(os.path.join(folder, "*.pcd")))  # what the shell gives for unpadded/*.pcd
        logs = []
        build(text_order, self.poses, self.out("from_glob"), TILE, self.config_yaml, SerialRunner(), log=logs.append)
        warned = [m for m in logs if m.startswith("warning: --poses: ")]
        self.assertEqual(len(warned), 1, logs)
        self.assertIn("f_20.pcd' is given before '", warned[0])
        self.assertIn("give the folder '%s' itself" % folder, warned[0])
        # Each tile of the map (and a merge of them) is marked as hpds's output: the folder leaves it out.
        tiles = [os.path.join(self.out("from_folder"), n) for n in tile_files(self.out("from_folder"))]
        shutil.copy(tiles[0], os.path.join(folder, "tile.ply"))
        hpds.ply.merge(tiles, os.path.join(folder, "merged.ply"))
        points = hpds.read_cloud(self.frames[0])
        hpds.ply.write(os.path.join(folder, "mine.ply"), points)  # a frame of the user's: not marked, so taken
        inputs, notes = hpds._hpds.expand_inputs([folder])
        self.assertEqual([os.path.basename(p) for p in inputs],
                         ["f_0.pcd", "f_4.pcd", "f_8.pcd", "f_12.pcd", "f_16.pcd", "f_20.pcd", "mine.ply"])
        self.assertIn("tile.ply' left out of folder", notes)
        self.assertIn("merged.ply' left out of folder", notes)
        with self.assertRaises(BuildError) as e:  # an empty folder, said as such
            os.makedirs(self.out("no_frames"))
            build([self.out("no_frames")], self.poses, self.out("e7"), TILE, self.config_yaml, SerialRunner(),
                  log=lambda m: None)
        self.assertIn("holds no .pcd, .ply or .bin frame", str(e.exception))

    def test_an_empty_map_says_why(self):
        # NaN-only frames gave "wrote 0 samples" and exit 0 with nothing said.
        folder = self.out("nan_frames")
        os.makedirs(folder)
        cloud = hpds.read_cloud(self.frames[0])[:40].copy()
        cloud["x"] = np.nan
        for i in range(2):
            hpds.ply.write(os.path.join(folder, "f_%d.ply" % i), cloud)
        poses = os.path.join(folder, "poses.txt")
        with open(poses, "w") as f:
            f.write("1 0 0 0 0 1 0 0 0 0 1 0\n" * 2)
        with contextlib.redirect_stderr(io.StringIO()) as err, contextlib.redirect_stdout(io.StringIO()):
            rc = map_build.main([folder, "--poses", poses, "-o", self.out("empty_map"), "--tile-size", "8",
                                 "--workers", "0"] + SAMPLING)
        self.assertEqual(rc, 0)
        self.assertIn("warning: the map holds no sample: of 80 input points, 80 were NaN/Inf", err.getvalue())

    def test_command_line_errors_name_the_option_or_key(self):
        base = self.frames[:2] + ["--poses", self.poses, "--workers", "0"]
        cases = [
            (["-o", self.out("e1"), "--tile-size", "3", "--cell-size", "2"], "tile size"),
            (["-o", self.out("e2"), "--tile-size", "8", "--mode", "scan"], "--mode"),
            (["-o", self.out("e3"), "--tile-size", "8", "--cell-size", "-1"], "hierarchy.cell_size"),
            (["-o", self.out("e4"), "--tile-size", "8", "--order", "best"], "order.type"),
        ]
        for args, what in cases:
            with self.subTest(what=what):
                with contextlib.redirect_stderr(io.StringIO()) as err:
                    self.assertEqual(map_build.main(base + args), 1)
                self.assertIn(what, err.getvalue())
        with contextlib.redirect_stderr(io.StringIO()) as err:  # 2 inputs, 6 poses
            self.assertEqual(map_build.main(base + ["-o", self.out("e5"), "--tile-size", "8", "--cell-size", "2"]), 1)
        self.assertIn("poses", err.getvalue())
        # A config's `ros:` section is checked as the node checks the file (a trial found `hpds sample --config`
        # accepting what the node refuses; the map build judged only the sampling keys too).
        node_bad = self.out("node_bad.yaml")
        with open(node_bad, "w") as f:
            f.write("ros:\n  queue_size: 0\n")
        with contextlib.redirect_stderr(io.StringIO()) as err:
            self.assertEqual(map_build.main(base + ["-o", self.out("e8"), "--tile-size", "8", "--config", node_bad]), 1)
        self.assertIn("ros.queue_size: must be in 1..1000, got 0 (in %s)" % node_bad, err.getvalue())
        # --spacing 0 was taken as output.spacing 0 ("not set") and built every level down to max_depth, exit 0; a
        # bad command line, as in `hpds sample`.
        for spacing in ("0", "-0.1", "nan"):
            with self.subTest(spacing=spacing):
                with contextlib.redirect_stderr(io.StringIO()) as err, self.assertRaises(SystemExit) as stop:
                    map_build.main(base + ["-o", self.out("e6"), "--tile-size", "8", "--spacing", spacing])
                self.assertEqual(stop.exception.code, 2)
                self.assertIn("--spacing: must be a finite number in (0, 1e+06]", err.getvalue())
                self.assertFalse(os.path.exists(self.out("e6")))

    def test_the_shipped_defaults_round_the_tile_size_to_whole_cells(self):
        # The README's command: no --cell-size, so the cell is derived from output.spacing (3.695 m for 0.1 m), an
        # odd size that no round tile size divides. The tile size is rounded to whole cells (said on stderr) rather
        # than refused; a cell the user fixed is still checked exactly (test_command_line_errors_name_the_option_or_key).
        base = self.frames + ["--poses", self.poses, "--workers", "0", "--spacing", "0.1"]
        with contextlib.redirect_stderr(io.StringIO()) as err:
            self.assertEqual(map_build.main(base + ["-o", self.out("d1"), "--tile-size", "8"]), 0, err.getvalue())
        with open(os.path.join(self.out("d1"), "manifest.json")) as f:
            manifest = json.load(f)
        cell = manifest["cell_size"]
        self.assertAlmostEqual(cell, 2 * 0.1 / math.sqrt(3) * 2 ** 5, places=6)
        self.assertEqual(manifest["tile_size"], 2 * cell)  # 8 / 3.695 = 2.17 cells: 2
        self.assertIn("tiles of %.9g m (2 cells) instead" % (2 * cell), err.getvalue())
        self.assertGreater(manifest["counts"]["samples_written"], 0)
        # A size that is already whole cells is taken as it is, without a word.
        with contextlib.redirect_stderr(io.StringIO()) as err:
            self.assertEqual(map_build.main(base + ["-o", self.out("d2"), "--tile-size", repr(3 * cell)]), 0)
        self.assertNotIn("instead", err.getvalue())
        # Beyond 2^20 cells: refused, and not first announced as rounded (the two lines contradicted each other).
        with contextlib.redirect_stderr(io.StringIO()) as err:
            self.assertNotEqual(map_build.main(base + ["-o", self.out("d3"), "--tile-size", "1e9"]), 0)
        self.assertIn("tile size: must be a whole multiple (>= 1, <= 2^20)", err.getvalue())
        self.assertNotIn("instead", err.getvalue())

    def two_poses(self, name, dx=0.0):
        """The drive's first two poses, moved by dx along x."""
        with open(self.poses) as f:
            rows = [list(map(float, line.split())) for line in f if line.strip()][:2]
        path = self.out(name)
        with open(path, "w") as f:
            for r in rows:
                r[3] += dx
                f.write(" ".join(repr(v) for v in r) + "\n")
        return path

    def test_frames_with_other_fields_are_refused_even_in_other_tasks(self):
        # A synthetic frame (x y z intensity ring time) and a KITTI .bin (x y z intensity), bucketed by separate
        # tasks: as `hpds sample --mode map` does, the build refuses them instead of writing tiles of two layouts.
        kitti = self.out("other_fields.bin")
        support.write_kitti_bin(kitti, hpds.read_points(self.frames[1]))
        with self.assertRaises(BuildError) as e:
            build([self.frames[0], kitti], self.two_poses("poses_mixed.txt"), self.out("mixed"), TILE,
                  self.config_yaml, SerialRunner(), chunk_frames=1, log=lambda m: None)
        self.assertIn("point fields or their layout differ", str(e.exception))
        self.assertIn("other_fields.bin", str(e.exception))
        self.assertEqual(tile_files(self.out("mixed")), [])
        self.assertFalse(os.path.exists(os.path.join(self.out("mixed"), ".hpds_work")))
        # The build made the folder and wrote no tile: the folder goes with its lock file. A folder that was there
        # stays, with whatever it held.
        self.assertFalse(os.path.exists(self.out("mixed")))
        os.makedirs(self.out("kept"))
        with self.assertRaises(BuildError):
            build([self.frames[0], kitti], self.two_poses("poses_mixed.txt"), self.out("kept"), TILE,
                  self.config_yaml, SerialRunner(), chunk_frames=1, log=lambda m: None)
        self.assertTrue(os.path.isdir(self.out("kept")))
        # An output path that is a file is said as such (it was a bare '[Errno 17] File exists').
        with open(self.out("a_file"), "w") as f:
            f.write("x")
        with self.assertRaises(BuildError) as e:
            build([self.frames[0], kitti], self.two_poses("poses_mixed.txt"), self.out("a_file"), TILE,
                  self.config_yaml, SerialRunner(), chunk_frames=1, log=lambda m: None)
        self.assertIn("is a file", str(e.exception))
        with open(self.out("a_file")) as f:
            self.assertEqual(f.read(), "x")

    def test_empty_frames_of_other_fields_are_taken(self):
        # A driver's empty x y z cloud before the first scan, and another at the end: as in `hpds sample --mode map`,
        # frames without points neither fix the layout nor have to match it, in one bucketing task or in their own.
        empty = self.out("empty_xyz.pcd")
        with open(empty, "w") as f:
            f.write("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 0\n"
                    "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 0\nDATA ascii\n")
        with open(self.poses) as f:
            rows = [line for line in f if line.strip()][:2]
        poses = self.out("poses_with_empty.txt")
        with open(poses, "w") as f:
            f.writelines([rows[0]] + rows[:2] + [rows[1]])
        for chunk in (1, None):
            out = self.out("with_empty_%s" % chunk)
            manifest = build([empty] + self.frames[:2] + [empty], poses, out, TILE, self.config_yaml, SerialRunner(),
                             chunk_frames=chunk, log=lambda m: None)
            self.assertGreater(len(tile_files(out)), 0, chunk)
            self.assertEqual(manifest["counts"]["input_points"], sum(len(hpds.read_points(p)) for p in self.frames[:2]))
            self.assertEqual(manifest["frames"], 4)

    def test_a_pcd_viewpoint_turns_the_normals_and_a_far_one_is_warned(self):
        # `hpds sample` turns normals toward a PCD's VIEWPOINT (the sensor's position in the frame's coordinates); the
        # bucket files keep it beside the pose, so a tiled build does the same. A viewpoint a kilometre from every
        # point (world coordinates without the sensor's position) is warned about, as `hpds sample` warns.
        with open(self.frames[1], "rb") as f:
            data = f.read()
        start = data.index(b"VIEWPOINT")
        end = data.index(b"\n", start)

        def moved(name, viewpoint):
            path = self.out(name)
            with open(path, "wb") as f:
                f.write(data[:start] + b"VIEWPOINT " + viewpoint + b" 1 0 0 0" + data[end:])
            return path

        def run(second, tag):
            lines = []
            out = self.out(tag)
            build([self.frames[0], second], self.two_poses("poses_%s.txt" % tag), out, TILE, self.config_yaml,
                  SerialRunner(), chunk_frames=1, log=lines.append)
            tiles = [hpds.ply.read(os.path.join(out, n)) for n in tile_files(out)]
            samples = np.concatenate(tiles)
            samples = samples[np.lexsort((samples["z"], samples["y"], samples["x"]))]
            return samples, "\n".join(lines)

        plain, plain_log = run(self.frames[1], "vp_plain")
        turned, turned_log = run(moved("vp_above.pcd", b"0 0 40"), "vp_above")
        far, far_log = run(moved("vp_far.pcd", b"5000 0 0"), "vp_far")
        for log in (plain_log, turned_log):
            self.assertNotIn("from its viewpoint", log)
        self.assertIn("vp_far.pcd' is ", far_log)
        self.assertIn("from its viewpoint (5000, 0, 0)", far_log)
        self.assertIn("set each PCD's VIEWPOINT", far_log)
        for other in (turned, far):
            # The same samples; only the direction the normals face may differ.
            for axis in ("x", "y", "z"):
                np.testing.assert_array_equal(other[axis], plain[axis])
        dot = lambda a, b: a["normal_x"] * b["normal_x"] + a["normal_y"] * b["normal_y"] + a["normal_z"] * b["normal_z"]
        valid = np.isfinite(plain["normal_x"])
        self.assertGreater(int(np.sum(dot(turned, plain)[valid] < 0)), 10, "a viewpoint 40 m up turned no normal")
        self.assertGreater(int(np.sum(dot(far, plain)[valid] < 0)), 10)

    def test_far_poses_write_float64_unless_float32_is_asked_and_then_warn(self):
        # 1e7 m along x: float32 x y z round by 0.6 m, against an output radius of 0.11 m.
        poses = self.two_poses("poses_far.txt", dx=1e7)
        base = self.frames[:2] + ["--poses", poses, "--tile-size", str(TILE), "--workers", "0"] + SAMPLING
        for flags, warned in (([], False), (["--float64-xyz"], False), (["--float32-xyz"], True)):
            with self.subTest(flags=flags):
                out = self.out("far%s" % "".join(flags))
                with contextlib.redirect_stderr(io.StringIO()) as err:
                    self.assertEqual(map_build.main(base + ["-o", out] + flags), 0)
                self.assertEqual("float64_xyz" in err.getvalue(), warned, err.getvalue())
                # The widening is said where it happens, with the flag that keeps float32.
                self.assertEqual("written as float64" in err.getvalue(), not flags, err.getvalue())
                with open(os.path.join(out, "manifest.json")) as f:
                    rounding = json.load(f)["position_rounding"]
                tile = hpds.ply.read(os.path.join(out, tile_files(out)[0]))
                if warned:
                    self.assertGreater(rounding, 0.5)
                    self.assertEqual(tile.dtype["x"], np.dtype("<f4"))
                else:
                    self.assertEqual(rounding, 0.0)
                    self.assertEqual(tile.dtype["x"], np.dtype("<f8"))
                    self.assertGreater(tile["x"].min(), 1e7 - 100)

    def test_normals_and_covariances_flags(self):
        base = self.frames[:2] + ["--poses", self.two_poses("poses_flags.txt"), "--tile-size", str(TILE),
                                  "--workers", "0", "--cell-size", str(CELL), "--max-depth", "5", "--level", "4"]
        for flags, field, present in ((["--no-normals"], "normal_x", False), ([], "normal_x", True),
                                      (["--covariances"], "cov_xx", True)):
            with self.subTest(flags=flags):
                out = self.out("flags%s" % "".join(flags))
                with contextlib.redirect_stderr(io.StringIO()):
                    self.assertEqual(map_build.main(base + ["-o", out] + flags), 0)
                names = hpds.ply.read(os.path.join(out, tile_files(out)[0])).dtype.names
                self.assertEqual(field in names, present, names)
        with contextlib.redirect_stderr(io.StringIO()) as err:
            self.assertEqual(map_build.main(base + ["-o", self.out("flags_bad"), "--covariances", "--no-normals"]), 1)
        self.assertIn("--covariances", err.getvalue())
        # A config whose combination only the flags make valid is judged with them, as `hpds sample` judges it.
        config = os.path.join(self.root, "normals_off_covariances_on.yaml")
        with open(config, "w") as f:
            f.write("normals:\n  enabled: false\n  covariances: true\n")
        with contextlib.redirect_stderr(io.StringIO()) as err:
            self.assertEqual(map_build.main(base + ["-o", self.out("flags_file"), "--config", config]), 1)
        self.assertIn("normals.covariances: needs normals.enabled", err.getvalue())
        self.assertIn("normals_off_covariances_on.yaml, with the flags over it", err.getvalue())
        with contextlib.redirect_stderr(io.StringIO()):
            self.assertEqual(map_build.main(base + ["-o", self.out("flags_mended"), "--config", config, "--normals"]), 0)
        self.assertIn("cov_xx", hpds.ply.read(os.path.join(self.out("flags_mended"), tile_files(self.out("flags_mended"))[0])).dtype.names)

    def test_only_the_output_folder_is_made_and_no_lock_file_stays(self):
        # Found in a user trial: a mistyped -o on a shared file system became a tree of folders holding a whole map,
        # and every finished build left its empty lock file.
        self.assertEqual(sorted(os.listdir(self.reference)), sorted(tile_files(self.reference) + ["manifest.json"]))
        deep = os.path.join(self.out("no_such_parent"), "out")
        with self.assertRaises(BuildError) as e:
            build(self.frames[:2], self.two_poses("poses_parent.txt"), deep, TILE, self.config_yaml, SerialRunner(),
                  log=lambda m: None)
        self.assertIn("does not exist", str(e.exception))
        self.assertIn("no_such_parent", str(e.exception))
        self.assertFalse(os.path.exists(self.out("no_such_parent")))
        with contextlib.redirect_stderr(io.StringIO()) as err:
            self.assertEqual(map_build.main(self.frames[:2] + ["--poses", self.two_poses("poses_parent.txt"),
                                                               "-o", deep, "--tile-size", str(TILE),
                                                               "--workers", "0"] + SAMPLING), 1)
        self.assertIn("does not exist", err.getvalue())
        self.assertFalse(os.path.exists(self.out("no_such_parent")))
        # A lock file a killed build left (the lock itself went with its process) does not stop a build, which
        # removes it at its end.
        out = self.out("stale_lock")
        os.makedirs(out)
        open(os.path.join(out, ".hpds_build.lock"), "w").close()
        build(self.frames[:2], self.two_poses("poses_stale.txt"), out, TILE, self.config_yaml, SerialRunner(),
              log=lambda m: None)
        self.assertFalse(os.path.exists(os.path.join(out, ".hpds_build.lock")))
        self.assertTrue(os.path.exists(os.path.join(out, "manifest.json")))

    def test_a_second_build_into_a_folder_in_use_is_refused(self):
        out = self.out("locked")
        os.makedirs(os.path.join(out, ".hpds_work", "buckets"))  # the running build's scratch
        with open(os.path.join(out, "tile_0_0.ply"), "w") as f:  # and a tile it has finished (not a leftover)
            f.write("ply\n")
        with open(os.path.join(out, ".hpds_build.lock"), "a") as held:
            fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)
            with self.assertRaises(BuildError) as e:
                build(self.frames[:2], self.two_poses("poses_locked.txt"), out, TILE, self.config_yaml,
                      SerialRunner(), log=lambda m: None)
            self.assertIn("another tiled build", str(e.exception))
            self.assertTrue(os.path.isdir(os.path.join(out, ".hpds_work", "buckets")), "the other build's scratch")
            # The command line too: refused, and the other build's scratch is left alone.
            with contextlib.redirect_stderr(io.StringIO()) as err:
                self.assertEqual(map_build.main(self.frames[:2] + ["--poses", self.two_poses("poses_locked.txt"),
                                                                   "-o", out, "--tile-size", str(TILE),
                                                                   "--workers", "0"] + SAMPLING), 1)
            self.assertIn("another tiled build", err.getvalue())
            self.assertTrue(os.path.isdir(os.path.join(out, ".hpds_work", "buckets")))

    def test_an_interrupted_build_leaves_no_scratch_and_says_so(self):
        class StopAtTiles(SerialRunner):
            """Interrupts the build when its tiles start (the buckets, a copy of the input, are on disk)."""

            def __init__(self, stop):
                super().__init__()
                self.stop, self.calls = stop, 0

            def run(self, tasks):
                self.calls += 1
                if self.calls == 2:
                    self.stop()
                return super().run(tasks)

        def ctrl_c():
            raise KeyboardInterrupt

        def sigterm():
            os.kill(os.getpid(), signal.SIGTERM)  # main's handler raises SystemExit here

        args = self.frames[:2] + ["--poses", self.two_poses("poses_stop.txt"), "--tile-size", str(TILE),
                                  "--workers", "0"] + SAMPLING
        for name, stop, code in (("ctrl_c", ctrl_c, 130), ("sigterm", sigterm, 128 + signal.SIGTERM)):
            with self.subTest(name=name):
                out = self.out("stopped_" + name)
                original = map_build.SerialRunner
                map_build.SerialRunner = lambda: StopAtTiles(stop)
                try:
                    with contextlib.redirect_stderr(io.StringIO()) as err:
                        self.assertEqual(map_build.main(args + ["-o", out]), code)
                finally:
                    map_build.SerialRunner = original
                self.assertIn("no manifest", err.getvalue())
                # Stopped before any tile: the folder it made is gone, and the message says so (it said "the
                # tiles written so far are incomplete").
                self.assertFalse(os.path.exists(out))
                self.assertIn("(nothing of this build is left)", err.getvalue())
                self.assertFalse(os.path.exists(os.path.join(out, ".hpds_work")))
                self.assertFalse(os.path.exists(os.path.join(out, "manifest.json")))
        self.assertEqual(signal.getsignal(signal.SIGTERM), signal.SIG_DFL)

    def test_ctrl_c_and_sigterm_to_the_process_group_stop_dask_workers_quietly(self):
        # A terminal's Ctrl-C, `timeout` and systemd signal the whole process group: the Dask worker processes printed
        # two screens of tracebacks after the build's own message. They now leave the stopping to this process.
        drive = self.out("group_drive")
        support.run([support.CLI, "synth", "-o", drive, "--frames", "80"])
        for sig, code in ((signal.SIGINT, 130), (signal.SIGTERM, 128 + signal.SIGTERM)):
            with self.subTest(signal=sig.name):
                out = self.out("group_" + sig.name)
                p = subprocess.Popen([sys.executable, "-m", "hpds.map_build", drive, "--poses",
                                      os.path.join(drive, "poses.txt"), "-o", out, "--tile-size", "32",
                                      "--workers", "2"], stderr=subprocess.PIPE, text=True, start_new_session=True)
                lines = []
                for line in p.stderr:
                    lines.append(line)
                    if line.startswith("hpds.map_build: bucketing"):
                        os.killpg(p.pid, sig)
                        break
                _, rest = p.communicate(timeout=120)
                err = "".join(lines) + rest
                self.assertEqual(p.returncode, code, err)
                self.assertIn("no manifest was written", err)
                self.assertNotIn("Traceback", err)
                self.assertNotIn("ERROR", err)
                self.assertFalse(os.path.exists(os.path.join(out, "manifest.json")))

    def test_tiles_of_an_incomplete_build_are_named_as_such(self):
        out = self.out("incomplete")
        os.makedirs(os.path.join(out, ".hpds_work"))
        shutil.copy(os.path.join(self.reference, tile_files(self.reference)[0]), os.path.join(out, "tile_0_0.ply"))
        with self.assertRaises(BuildError) as e:
            build(self.frames[:2], self.two_poses("poses_inc.txt"), out, TILE, self.config_yaml, SerialRunner(),
                  log=lambda m: None)
        self.assertIn("incomplete", str(e.exception))
        self.assertIn(".hpds_work", str(e.exception))


if __name__ == "__main__":
    unittest.main()
