"""The tiled map build, planned and run: bucketing tasks, then one task per tile in four colour phases, then one
output task per tile, then the manifest. The work of each task is C++ (hpds/tiling/); this module decides what runs
after what and where the files go. The tiling rule, why it is exact, memory and speed: docs/scaling.md.

    OUTDIR/tile_<i>_<j>.ply     each tile's samples of the output levels (the `hpds sample` PLY layout)
    OUTDIR/manifest.json        tiles, bounds, counts, config; written last: the build is complete when it exists
    OUTDIR/.hpds_work/          buckets, tile maps and border files while the build runs (removed at the end, and
                                when the build fails or is interrupted)
    OUTDIR/.hpds_build.lock     held while a build runs (removed at its end): a second build into the same folder
                                is refused
"""
import fcntl
import glob
import json
import os
import re
import shutil
import sys
import time

import numpy as np

from . import _hpds
from .runners import BuildError, Task

WORK_DIR = ".hpds_work"
LOCK = ".hpds_build.lock"
MANIFEST = "manifest.json"
_TILE_PLY = re.compile(r"tile_-?\d+_-?\d+\.ply$")


# Task bodies: module-level functions, so that Dask ships them to workers by reference. Each result carries the
# task's thread CPU time (the C++ work runs in the calling thread with threads: 1), for the run statistics.
_memory_kept = False
_memory_asked = False


def keep_freed_memory_in_workers():
    """Makes malloc keep freed memory in a Dask worker process (once per process; elsewhere nothing). Dask's nanny
    starts workers with MALLOC_TRIM_THRESHOLD_ set, which turns off glibc's adaptive thresholds: every task then
    mapped and unmapped its scratch (sys time 0.85 -> 7.9 s on a 40-frame drive), and a 1-worker build took 2.8x the
    time of --workers 0. A worker runs nothing but these tasks, as the CLI and the node run nothing but frames."""
    global _memory_kept, _memory_asked
    if _memory_asked:
        return _memory_kept
    try:
        from distributed import get_worker
        get_worker()
    except (ImportError, ValueError):
        return False  # not in a Dask worker: the caller's process keeps its own policy
    _memory_asked = True
    _memory_kept = _hpds.keep_freed_frame_memory()
    return _memory_kept


def _timed(fn, *args):
    keep_freed_memory_in_workers()
    c0 = time.thread_time()
    result = fn(*args)
    result["cpu_seconds"] = time.thread_time() - c0
    return result


def bucket_task(config_yaml, tile_size, inputs, poses, first_frame, out_dir):
    return _timed(_hpds.bucket_frames, config_yaml, tile_size, inputs, poses, first_frame, out_dir)


def build_task(config_yaml, tile_size, i, j, buckets, borders, map_path, border_path):
    return _timed(_hpds.build_tile, config_yaml, tile_size, i, j, buckets, borders, map_path, border_path)


def finish_task(config_yaml, tile_size, i, j, map_path, borders, ply_path):
    return _timed(_hpds.finish_tile, config_yaml, tile_size, i, j, map_path, borders, ply_path)


def _critical_path(tasks, results, start):
    """CPU seconds of the longest dependency chain of `tasks` (listed after their dependencies), from `start`."""
    end = {}
    for t in tasks:
        end[t.key] = max([start] + [end[d] for d in t.deps]) + results[t.key]["cpu_seconds"]
    return max(end.values(), default=start)


def phase(key):
    """Colour phase of tile (i, j): tiles of one phase never touch."""
    return (key[0] & 1) | ((key[1] & 1) << 1)


def tile_ply_name(key):
    return "tile_%d_%d.ply" % key


def tile_plys(outdir):
    """The names of the tile PLYs in OUTDIR (a build's own or an earlier one's), sorted."""
    return sorted(os.path.basename(p) for p in glob.glob(os.path.join(glob.escape(outdir), "tile_*_*.ply"))
                  if _TILE_PLY.match(os.path.basename(p)))


def check_paths(inputs, outdir):
    """Refuses a build that would overwrite an input or an earlier build's output (hpds never destroys data)."""
    if os.path.exists(outdir) and not os.path.isdir(outdir):
        raise BuildError("output folder '%s' is a file: choose a folder (it is made when missing)" % outdir)
    # Only the folder itself is made: a mistyped path on a shared file system must not become a tree of folders.
    parent = os.path.dirname(os.path.abspath(outdir))
    if not os.path.isdir(parent):
        raise BuildError("output folder '%s': the folder that would hold it, '%s', does not exist" % (outdir, parent))
    out = os.path.realpath(outdir)
    work = os.path.join(out, WORK_DIR)
    for p in inputs:
        real = os.path.realpath(p)
        if os.path.dirname(real) == out and (_TILE_PLY.match(os.path.basename(real)) or
                                             os.path.basename(real) == MANIFEST):
            raise BuildError("input '%s' has the name of an output of the build in %s" % (p, outdir))
        if real == work or real.startswith(work + os.sep):
            raise BuildError("input '%s' lies in the build's work folder %s" % (p, work))
    earlier = tile_plys(outdir)
    if os.path.exists(os.path.join(outdir, MANIFEST)):
        earlier.insert(0, MANIFEST)
    if earlier:
        shown = ", ".join(earlier[:3]) + (", ..." if len(earlier) > 3 else "")
        if MANIFEST in earlier:
            raise BuildError("%s already holds a tiled build (%s): choose another output folder or move those files "
                             "away; hpds never overwrites them" % (outdir, shown))
        raise BuildError("%s holds the tiles of an incomplete tiled build (%s; no %s): choose another output folder, "
                         "or delete them%s; hpds never overwrites them"
                         % (outdir, shown, MANIFEST, " and its scratch folder " + WORK_DIR
                            if os.path.isdir(os.path.join(outdir, WORK_DIR)) else ""))


def remove_scratch(outdir):
    """Removes a build's scratch folder (the buckets are a copy of the input): after the build, when it failed or
    was interrupted. Complete tiles stay; without a manifest the build is marked incomplete."""
    shutil.rmtree(os.path.join(outdir, WORK_DIR), ignore_errors=True)


def remove_scratch_unless_building(outdir):
    """remove_scratch, unless another build holds OUTDIR's lock (then the scratch is that build's)."""
    if not os.path.isdir(os.path.join(outdir, WORK_DIR)):
        return
    try:
        lock = _lock(outdir)
    except BuildError:
        return
    try:
        remove_scratch(outdir)
    finally:
        _unlock(lock, outdir)


def _lock(outdir):
    """An exclusive lock on OUTDIR/.hpds_build.lock for the build's duration (released when the file is closed, also
    when the process dies), so that a second build into the same folder cannot remove the first one's scratch.
    A build removes the file when it ends (_unlock): a lock taken on a file that was removed meanwhile is no lock,
    so it is taken again on the file at the path."""
    path = os.path.join(outdir, LOCK)
    while True:
        try:
            f = open(path, "a")
        except PermissionError:
            # The folder, not the lock file the user never asked for.
            raise BuildError("the output folder %s is not writable" % outdir) from None
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            f.close()
            raise BuildError("another tiled build is writing to %s (it holds %s): wait for it, or choose another "
                             "output folder" % (outdir, LOCK))
        try:
            if os.stat(path).st_ino == os.fstat(f.fileno()).st_ino:
                return f
        except FileNotFoundError:
            pass
        f.close()


def _unlock(lock, outdir):
    """Removes the lock file, still held, then lets it go: a finished or failed build leaves no file of its own.
    Once only: after the release the file at the path may be another build's."""
    if lock.closed:
        return
    path = os.path.join(outdir, LOCK)
    try:
        if os.stat(path).st_ino == os.fstat(lock.fileno()).st_ino:
            os.remove(path)
    except OSError:
        pass
    lock.close()


def _refuse_if_building(outdir):
    """Refuses a build into a folder another build is writing (its tiles are live, not an incomplete build's): the
    lock taken and let go at once, before check_paths would call those tiles leftovers."""
    if os.path.isfile(os.path.join(outdir, LOCK)):
        _lock(outdir).close()


def _check_layouts(bucketed, chunks, inputs):
    """Every frame with points must have the point layout of the first frame with points: each bucketing task
    checks its own frames, this compares the tasks (a task whose frames were all empty has none and takes any)."""
    first = first_at = None
    for c, (a, b) in enumerate(chunks):
        layout = bucketed["bucket-%d" % c]["layout"]
        if layout is None:
            continue
        if first is None:
            first, first_at = layout, a
        elif layout != first:
            names = lambda l: " ".join(f[0] for f in l[0]) or "(none)"  # noqa: E731
            raise BuildError("frame's point fields or their layout differ from those of the first frame with points: "
                             "'%s' (one of frames %d..%d) has %s (%d bytes per point), '%s' (or a frame after it) has "
                             "%s (%d bytes per point); a tiled build needs one layout, byte for byte"
                             % (inputs[a], a, b - 1, names(layout), layout[1], inputs[first_at], names(first),
                                first[1]))


def _chunks(n, workers, chunk_frames):
    if chunk_frames is None:
        # A few bucketing tasks per worker (balance) with a bounded number of frames in memory per task.
        chunk_frames = max(1, min(16, -(-n // max(1, 2 * max(workers, 1)))))
    return [(a, min(n, a + chunk_frames)) for a in range(0, n, chunk_frames)]


def _add_counters(total, part):
    for k, v in part.items():
        total[k] = total.get(k, 0) + v


def _write_json(path, data):
    tmp = "%s.tmp.%d" % (path, os.getpid())
    with open(tmp, "w") as f:
        json.dump(data, f, indent=1, sort_keys=False)
        f.write("\n")
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def build(inputs, poses_path, outdir, tile_size, config_yaml, runner, chunk_frames=None, log=None, other_inputs=()):
    """Runs a tiled map build (see the module docstring) and returns the manifest as a dict.

    inputs: point-cloud files, one frame each, in stream order, or folders of them (each taken in natural name
    order, as `hpds sample` takes a folder: frame_2 before frame_10); poses_path: KITTI or TUM poses, one per input;
    config_yaml: the complete config (hpds._hpds.config_yaml), map mode; runner: SerialRunner or DaskRunner;
    other_inputs: further files the build read (the config file), which it must not overwrite either.
    Raises BuildError (a task failed, or the paths are unsafe) or ValueError (config, tile size).
    """
    log = log or (lambda msg: print("hpds.map_build: " + msg, file=sys.stderr, flush=True))
    t_start = time.monotonic()
    plan = _hpds.tiled_plan(config_yaml, tile_size)
    try:
        inputs, notes = _hpds.expand_inputs([os.fspath(p) for p in inputs])
    except ValueError as e:  # a folder that cannot be read or holds no frame
        raise BuildError(str(e)) from None
    for note in notes.splitlines():
        log(note[len("hpds: "):] if note.startswith("hpds: ") else note)
    poses, corrected = _hpds.read_poses(os.fspath(poses_path))
    if corrected:
        log("warning: " + corrected)
    try:
        order = _hpds.check_poses_match_inputs(os.fspath(poses_path), len(poses), inputs)  # as the user gave them
    except ValueError as e:
        raise BuildError(str(e)) from None
    if order:
        log("warning: " + order)
    inputs = [os.path.abspath(p) for p in inputs]  # workers elsewhere see the same shared paths
    if len(poses):
        # Georeferenced poses: float64 x y z unless the config chose a type, as `hpds sample` does.
        config_yaml, note = _hpds.widen_xyz_for_poses(config_yaml, float(np.abs(poses[:, :3, 3]).max()),
                                                      "--float32-xyz (output.float32_xyz: true)")
        if note:
            log(note)
    read = inputs + [os.fspath(poses_path)] + [os.fspath(p) for p in other_inputs]
    _refuse_if_building(outdir)  # before check_paths, which would call a running build's files leftovers
    check_paths(read, outdir)  # before the folder is made, so that a refused build leaves nothing behind
    made = not os.path.exists(outdir)
    os.makedirs(outdir, exist_ok=True)
    outdir = os.path.abspath(outdir)
    lock = _lock(outdir)
    try:
        # Checked again under the lock: a build that finished meanwhile left its tiles.
        check_paths(read, outdir)
        remove_scratch(outdir)  # our own scratch from a killed build
        try:
            return _run(inputs, poses, poses_path, outdir, plan, tile_size, config_yaml, runner, chunk_frames, log,
                        t_start)
        except BaseException:
            # Failed, interrupted (Ctrl-C) or stopped (SIGTERM as SystemExit): the scratch goes, complete tiles stay.
            remove_scratch(outdir)
            # A folder this build made and left with nothing but its lock goes too.
            if made and os.listdir(outdir) == [LOCK]:
                _unlock(lock, outdir)
                try:
                    os.rmdir(outdir)
                except OSError:
                    pass
            raise
    finally:
        _unlock(lock, outdir)


def _run(inputs, poses, poses_path, outdir, plan, tile_size, config_yaml, runner, chunk_frames, log, t_start):
    work = os.path.join(outdir, WORK_DIR)
    os.makedirs(os.path.join(work, "tiles"))

    # 1. Bucketing: frames in chunks, each point filed under its tile.
    chunks = _chunks(len(inputs), runner.workers, chunk_frames)
    log("bucketing %d frames in %d tasks (tiles of %g m)" % (len(inputs), len(chunks), plan["tile_size"]))
    tasks = [Task("bucket-%d" % c, "bucketing frames %d..%d" % (a, b - 1), bucket_task,
                  (config_yaml, tile_size, inputs[a:b], poses[a:b], a, os.path.join(work, "buckets", "c%05d" % c)), [])
             for c, (a, b) in enumerate(chunks)]
    t0 = time.monotonic()
    bucketed = runner.run(tasks)
    _check_layouts(bucketed, chunks, inputs)
    seconds = {"bucketing": time.monotonic() - t0}
    counters, buckets, points = {}, {}, {}
    for c in range(len(chunks)):
        result = bucketed["bucket-%d" % c]
        _add_counters(counters, result["counters"])
        for i, j, n, path in result["tiles"]:
            buckets.setdefault((i, j), []).append(path)
            points[(i, j)] = points.get((i, j), 0) + n
    tiles = sorted(buckets, key=lambda k: (k[1], k[0]))
    far = next((bucketed["bucket-%d" % c]["far_viewpoint"] for c in range(len(chunks))
                if bucketed["bucket-%d" % c]["far_viewpoint"] is not None), None)
    if far is not None:
        # As `hpds sample` warns: frames in world coordinates without their sensor's position get normals that face
        # a point kilometres away (about half of them turned around), and range limits measure from it.
        log("warning: " + far + "the frames seem not to be in their sensor's frame; give them in the sensor's frame "
            "with --poses, or set each PCD's VIEWPOINT to its sensor's position")

    # 2. Tiles: phase by phase, each after its neighbours of earlier phases; 3. outputs, after all neighbours.
    def map_path(k):
        return os.path.join(work, "tiles", "tile_%d_%d.hpdsmap" % k)

    def border_path(k):
        return os.path.join(work, "tiles", "tile_%d_%d.border" % k)

    def near(k, ring):
        return [tuple(n) for n in _hpds.tile_neighbours(config_yaml, tile_size, k[0], k[1], ring) if tuple(n) in buckets]

    tasks = []
    for p in range(4):
        for k in tiles:
            if phase(k) != p:
                continue
            earlier = [n for n in near(k, plan["insertion_ring"]) if phase(n) < p]
            tasks.append(Task("build-%d_%d" % k, "tile (%d, %d), phase %d" % (k + (p,)), build_task,
                              (config_yaml, tile_size, k[0], k[1], buckets[k], [border_path(n) for n in earlier],
                               map_path(k), border_path(k)), ["build-%d_%d" % n for n in earlier]))
    for k in tiles:
        around = near(k, plan["normal_ring"]) if plan["normal_ring"] > 0 else []
        borders = [border_path(n) for n in around]
        tasks.append(Task("finish-%d_%d" % k, "output of tile (%d, %d)" % k, finish_task,
                          (config_yaml, tile_size, k[0], k[1], map_path(k), borders,
                           os.path.join(outdir, tile_ply_name(k))),
                          ["build-%d_%d" % k] + ["build-%d_%d" % n for n in around]))
    log("building %d tiles in 4 phases on %s" % (len(tiles), "%d workers" % runner.workers if runner.workers
                                                 else "this process"))
    t0 = time.monotonic()
    done = runner.run(tasks)
    seconds["tiles"] = time.monotonic() - t0
    bucket_cpu = [r["cpu_seconds"] for r in bucketed.values()]
    cpu = {"bucketing": sum(bucket_cpu),
           "tiles": sum(done[t.key]["cpu_seconds"] for t in tasks if t.key.startswith("build-")),
           "outputs": sum(done[t.key]["cpu_seconds"] for t in tasks if t.key.startswith("finish-")),
           # What any number of workers still runs one after another: the longest bucketing task, then the longest
           # chain of tiles and outputs. total / critical_path bounds the speed-up.
           "critical_path": _critical_path(tasks, done, max(bucket_cpu, default=0.0))}

    # 4. The manifest, last: its presence marks a complete build.
    depth = plan["output_level"]
    per_level = [0] * (depth + 1)
    lo, hi = [float("inf")] * 3, [float("-inf")] * 3
    entries = []
    peak = 0
    counts = {"input_points": counters.get("input", 0), "skipped_invalid": counters.get("skipped_invalid", 0),
              "skipped_zero": counters.get("skipped_zero", 0), "skipped_range": counters.get("skipped_range", 0),
              "out_of_range": counters.get("out_of_range", 0), "dropped_depth": 0, "samples_built": 0}
    for k in tiles:
        b, f = done["build-%d_%d" % k], done["finish-%d_%d" % k]
        counts["dropped_depth"] += b["counters"]["dropped_depth"]
        counts["samples_built"] += b["samples"]
        peak = max(peak, b["memory_bytes"])
        for d, n in enumerate(f["samples_per_level"]):
            per_level[d] += n
        if f["samples"]:
            lo = [min(a, v) for a, v in zip(lo, f["bounds"][:3])]
            hi = [max(a, v) for a, v in zip(hi, f["bounds"][3:])]
        entries.append({"i": k[0], "j": k[1], "phase": phase(k), "file": tile_ply_name(k),
                        "bounds_xy": _hpds.tile_bounds(config_yaml, tile_size, k[0], k[1]),
                        "points": points[k], "samples_built": b["samples"], "samples": f["samples"],
                        "samples_per_level": f["samples_per_level"], "invalid_normals": f["invalid_normals"]})
    counts["samples_written"] = sum(per_level)
    counts["samples_per_level"] = per_level
    rounding = max((done["finish-%d_%d" % k]["rounding"] for k in tiles), default=0.0)
    warning = _hpds.rounding_warning(rounding, plan["output_radius"], "output.float64_xyz: true (--float64-xyz)")
    if warning:
        log("warning: " + warning)
    seconds["total"] = time.monotonic() - t_start
    manifest = {
        "format": "hpds tiled map 1",
        "tile_size": plan["tile_size"], "cell_size": plan["cell_size"], "output_level": depth,
        "build_depth": plan["build_depth"], "frames": len(inputs),
        "bounds": {"min": lo, "max": hi} if counts["samples_written"] else None,
        "counts": counts, "tiles": entries, "position_rounding": rounding,
        "config": _hpds.config_dict(config_yaml, ""),
        "run": {"workers": runner.workers, "bucketing_tasks": len(chunks), "seconds": seconds,
                "task_cpu_seconds": cpu, "peak_tile_memory_bytes": peak},
    }
    _write_json(os.path.join(outdir, MANIFEST), manifest)
    remove_scratch(outdir)
    # Temporaries of output tasks whose worker died before the rename (AtomicFile's "<target>.hpds-tmp.<pid>.<n>"):
    # every task is done, so none is being written.
    for stale in glob.glob(os.path.join(glob.escape(outdir), "tile_*_*.ply.hpds-tmp.*")):
        os.remove(stale)
    return manifest
