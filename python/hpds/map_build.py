"""python3 -m hpds.map_build: a map-mode sampling of a whole drive, cut into tiles that run as Dask tasks.

    python3 -m hpds.map_build INPUT... --poses POSES.txt -o OUTDIR --tile-size T
        [--workers N | --scheduler ADDR] [--config FILE] [sampling options as in `hpds sample`]

Writes OUTDIR/tile_<i>_<j>.ply (the `hpds sample` PLY layout) and OUTDIR/manifest.json (written last). The union of
the tiles has the guarantees of one `hpds sample --mode map` run over the same frames (the samples may differ, as
the insertion order does). --workers N starts a local Dask cluster of N processes, --scheduler joins a running one
(every worker must see INPUT and OUTDIR at the same paths, and have hpds installed), --workers 0 runs in this
process without Dask.
"""
import argparse
import logging
import math
import os
import signal
import sys

from . import _hpds
from .config import to_yaml
from .runners import BuildError, DaskRunner, SerialRunner
from .tiled_build import MANIFEST, build, remove_scratch_unless_building, tile_plys


def parse_args(argv):
    p = argparse.ArgumentParser(prog="python3 -m hpds.map_build", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="frames: .pcd, .ply, KITTI .bin, in stream order; a folder stands for its frames in natural "
                        "name order (frame_2 before frame_10), as in hpds sample")
    p.add_argument("--poses", required=True, help="pose file, one sensor-to-world pose per input: KITTI (3x4 matrix per line) "
                   "or TUM (time x y z qx qy qz qw)")
    p.add_argument("-o", "--output", required=True, metavar="OUTDIR", help="output folder (tiles and manifest.json)")
    p.add_argument("--tile-size", required=True, type=float, metavar="T",
                   help="[m] tile edge, a whole multiple of hierarchy.cell_size; with the cell derived from "
                        "--spacing (no --cell-size), rounded to the nearest whole number of cells")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=None,
                       help="local Dask worker processes (default: one per core); 0 = no Dask, this process")
    where.add_argument("--scheduler", metavar="ADDR", help="address of a running Dask scheduler (tcp://host:8786)")
    p.add_argument("--chunk-frames", type=int, default=None, help="frames per bucketing task (default: automatic)")
    s = p.add_argument_group("sampling options (as in hpds sample)")
    s.add_argument("--config", help="YAML config (see config/hpds.yaml); flags override it")
    s.add_argument("--cell-size", type=float, help="[m] level-0 cell edge (hierarchy.cell_size)")
    s.add_argument("--max-depth", type=int, help="finest level 0..21 (hierarchy.max_depth)")
    lvl = s.add_mutually_exclusive_group()
    lvl.add_argument("--level", type=int, help="write levels 0..D (output.level)")
    lvl.add_argument("--spacing", type=float,
                     help="[m] output radius: samples at least S apart; exactly S (the cell derived from it) unless "
                          "--cell-size fixes the cell, then the coarsest level with r_D <= S (output.spacing)")
    s.add_argument("--normals", action=argparse.BooleanOptionalAction, default=None,
                   help="estimate PCA normals and curvature, or not (normals.enabled; default: the config's, on)")
    s.add_argument("--covariances", action="store_true",
                   help="also write GICP covariances cov_xx..cov_zz (normals.covariances; implies --normals)")
    xyz = s.add_mutually_exclusive_group()
    xyz.add_argument("--float64-xyz", action="store_true",
                     help="write x y z as float64 (output.float64_xyz): for georeferenced coordinates")
    xyz.add_argument("--float32-xyz", action="store_true",
                     help="write x y z as float32 even from float64 input (output.float32_xyz)")
    s.add_argument("--order", help="random | input | sphericity | surface_variation (order.type)")
    s.add_argument("--seed", type=int, help="seed of the random order (order.seed)")
    s.add_argument("--mode", help="map (a tiled build is a map build; scan is refused)")
    s.add_argument("--threads", type=int, help="threads per task (threads)")
    a = p.parse_args(argv)
    if a.workers is not None and a.workers < 0:
        p.error("--workers: must be >= 0")
    if a.chunk_frames is not None and a.chunk_frames < 1:
        p.error("--chunk-frames: must be >= 1")
    # As `hpds sample` checks it: output.spacing 0 in the config means "not set", which --spacing 0 must not
    # silently become (it built every level down to max_depth).
    if a.spacing is not None and not (0.0 < a.spacing <= 1e6):
        p.error("--spacing: must be a finite number in (0, 1e+06], got %g" % a.spacing)
    return a


def resolve_config(a):
    """Defaults, then --config FILE, then the flags, validated by the core: the complete config as YAML text."""
    if a.mode is not None and a.mode != "map":
        raise ValueError("--mode: a tiled build is a map build (only 'map' is accepted), got '%s'" % a.mode)
    # A tiled build keeps every sample of the map (each tile is built whole): the live node's memory bounds
    # (map.evict_distance, map.max_samples, on by default) do not apply to it.
    overlay = {"mode": "map", "map": {"evict_distance": 0.0, "max_samples": 0}}

    def put(section, key, value):
        if value is not None:
            overlay.setdefault(section, {})[key] = value

    put("hierarchy", "cell_size", a.cell_size)
    put("hierarchy", "max_depth", a.max_depth)
    put("output", "level", a.level)
    if a.spacing is not None:
        put("output", "level", -1)
        put("output", "spacing", a.spacing)
    if a.covariances and a.normals is False:
        raise ValueError("--covariances needs normals: it cannot go with --no-normals")
    put("normals", "enabled", True if a.covariances else a.normals)
    if a.covariances:
        put("normals", "covariances", True)
    # A flag overrides the config's choice of type, whichever of the two keys the config set.
    if a.float64_xyz or a.float32_xyz:
        put("output", "float64_xyz", a.float64_xyz)
        put("output", "float32_xyz", a.float32_xyz)
    put("order", "type", a.order)
    put("order", "seed", a.seed)
    if a.threads is not None:
        overlay["threads"] = a.threads
    return _hpds.config_yaml("", a.config or "", to_yaml(overlay))


def whole_cell_tile_size(tile_size, config_yaml, log=None):
    """--tile-size with a cell derived from output.spacing (hierarchy.cell_size 0): the cell is an odd size (3.695 m
    for 0.1 m) that no round tile size is a multiple of, so T is rounded to the nearest whole number (>= 1) of cells,
    and the build says so. A cell the config fixes is left to the tile grid's check, which refuses other sizes."""
    cell, derived = _hpds.tile_cell(config_yaml)
    if not derived or not math.isfinite(tile_size) or not tile_size > 0.0:
        return tile_size
    k = max(1, round(tile_size / cell))
    if k > 2 ** 20:
        # Left to the tile grid's refusal: announcing a rounded size just before refusing it contradicted itself.
        return tile_size
    rounded = k * cell
    if abs(rounded - tile_size) > 1e-9 * rounded and log is not None:
        log("tile size %g m is not a whole number of level-0 cells (%.9g m, derived from output.spacing): "
            "tiles of %.9g m (%d cell%s) instead" % (tile_size, cell, rounded, k, "" if k == 1 else "s"))
    return rounded


def _dask_runner(a):
    from distributed import Client, LocalCluster

    if a.scheduler:
        client = Client(a.scheduler)
        return DaskRunner(client), [client]
    workers = a.workers if a.workers is not None else (os.cpu_count() or 1)
    # Ctrl-C goes to the whole process group: each worker process printed two screens of KeyboardInterrupt tracebacks
    # after the build's own message. The workers start with SIGINT ignored (inherited through exec, and Python and
    # asyncio leave an ignored SIGINT alone); this process stops them when it is interrupted.
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    client = Client(cluster)
    return DaskRunner(client), [client, cluster]


def _stop_on_sigterm(signum, frame):
    # As SystemExit, so that the build's cleanup runs (the default action would end the process on the spot).
    raise SystemExit(128 + signum)


def _left_behind(outdir):
    """What a stopped build left in OUTDIR, for its last message: the build removes a folder it made and wrote no
    tile into, and keeps complete tiles otherwise."""
    tiles = tile_plys(outdir)
    if tiles:
        return " (%d tile%s written so far stay%s in %s, an incomplete build)" % (
            len(tiles), "" if len(tiles) == 1 else "s", "s" if len(tiles) == 1 else "", outdir)
    return " (nothing of this build is left%s)" % (" in " + outdir if os.path.isdir(outdir) else "")


def main(argv=None):
    a = parse_args(sys.argv[1:] if argv is None else argv)
    closers = []
    previous = signal.signal(signal.SIGTERM, _stop_on_sigterm)
    started = False
    try:
        config_yaml = resolve_config(a)
        tile_size = whole_cell_tile_size(a.tile_size, config_yaml,
                                         log=lambda msg: print("hpds.map_build: " + msg, file=sys.stderr, flush=True))
        if a.workers == 0:
            # This process runs the tasks itself, as `hpds sample` runs frames: the same malloc setting (task CPU
            # 7.6-8.1 -> 6.5-6.9 s on the scaling drive, resident set within 6 MB).
            _hpds.keep_freed_frame_memory()
            runner = SerialRunner()
        else:
            runner, closers = _dask_runner(a)
        started = True
        m = build(a.inputs, a.poses, a.output, tile_size, config_yaml, runner, chunk_frames=a.chunk_frames,
                  other_inputs=[a.config] if a.config else [])
    except (BuildError, ValueError, RuntimeError, OSError) as e:
        print("hpds.map_build: error: %s" % e, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("hpds.map_build: interrupted: no manifest was written%s" % _left_behind(a.output), file=sys.stderr)
        return 130
    except SystemExit as e:
        print("hpds.map_build: stopped by a signal: no manifest was written%s" % _left_behind(a.output),
              file=sys.stderr)
        return e.code
    finally:
        for c in closers:
            c.close()
        # Dask tasks still running when the build stopped may have written scratch after the build removed it.
        if started and not os.path.exists(os.path.join(a.output, MANIFEST)):
            remove_scratch_unless_building(a.output)
        signal.signal(signal.SIGTERM, previous)
    c = m["counts"]
    print("wrote %d samples (levels 0..%d) in %d tiles to %s (manifest.json); %d of %d points skipped, %d out of "
          "range, %d dropped below the build depth" %
          (c["samples_written"], m["output_level"], len(m["tiles"]), a.output,
           c["skipped_invalid"] + c["skipped_zero"] + c["skipped_range"], c["input_points"], c["out_of_range"],
           c["dropped_depth"]))
    if c["samples_written"] == 0:
        print("hpds.map_build: warning: the map holds no sample: of %d input points, %d were NaN/Inf, %d no-returns "
              "at (0,0,0), %d outside input.min_range/max_range, %d beyond the exact key range"
              % (c["input_points"], c["skipped_invalid"], c["skipped_zero"], c["skipped_range"], c["out_of_range"]),
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
