"""hpds: hierarchical additive Poisson-disk sampling of lidar point clouds, with PCA normals.

    import hpds
    samples = hpds.downsample(points)                    # points: (N, 3) float32 or float64 NumPy array
    samples = hpds.downsample(points, {"output": {"spacing": 0.2}, "normals": {"enabled": True}})
    samples = hpds.downsample(points, "config/hpds.yaml")
    points[samples["index"]], samples["level"]           # and samples["normal"], samples["curvature"]

The samples are those of the C++ one-call API (hpds/hpds.hpp): the samples `hpds sample` writes for the same points
and config, in the same order. A tiled map build of a whole drive runs with `python3 -m hpds.map_build`.
"""
import errno
import os
import warnings

import numpy as np

from . import _hpds
from . import ply
from .config import to_yaml

__all__ = ["Samples", "downsample", "load_config", "ply", "read_cloud", "read_points", "read_poses"]
__version__ = _hpds.__version__


class Samples(dict):
    """What downsample returns: a dict of per-sample arrays, plus `skipped`, the input points left out by reason
    ({"invalid": NaN/Inf, "zero": (0,0,0) no-returns, "range": outside input.min_range/max_range, "out_of_range":
    beyond the exact key range of the finest level}) and, in map mode, "evicted": samples given up to stay within
    map.max_samples; and `resolution`, what the call ran at ({"output_level": L, "radius": r_L in metres,
    "cell_size": the level-0 cell in metres}: the samples are levels 0..L, at least r_L apart). A copy is a Samples
    too."""

    skipped = None
    resolution = None

    def copy(self):
        out = Samples(self)
        out.skipped = dict(self.skipped) if self.skipped is not None else None
        out.resolution = dict(self.resolution) if self.resolution is not None else None
        return out


def _refuse_unreadable(path, what):
    """OSError subclasses a Python caller can catch as such, before the core's own message (a RuntimeError)."""
    if not os.path.exists(path):
        raise FileNotFoundError(errno.ENOENT, "%s does not exist" % what, path)
    if os.path.isdir(path):
        raise IsADirectoryError(errno.EISDIR, "%s is a folder" % what, path)


def _config_source(config):
    """(yaml_text, path) for the C++ side: a dict becomes YAML text, a path is read by the core."""
    if config is None:
        return "", ""
    if isinstance(config, (str, os.PathLike)):
        path = os.fspath(config)
        if not path:
            raise ValueError("config: empty path")
        _refuse_unreadable(path, "config file")
        return "", path
    return to_yaml(config), ""


def _xyz_of(points):
    """A structured array's float x y z fields as an (N, 3) array (float64 when any of them is), else `points`."""
    names = getattr(getattr(points, "dtype", None), "names", None)
    if not names:
        return points
    missing = [a for a in "xyz" if a not in names]
    if missing:
        raise TypeError("points: a structured array needs fields x, y and z; it has %s" % ", ".join(names))
    types = [points.dtype.fields[a][0] for a in "xyz"]
    if any(t.kind != "f" or t.shape != () for t in types):
        raise TypeError("points: fields x, y and z must be float32 or float64 scalars, got %s"
                        % ", ".join(str(t) for t in types))
    dtype = np.float64 if any(t.itemsize == 8 for t in types) else np.float32
    return np.stack([points[a].astype(dtype, copy=False) for a in "xyz"], axis=1)


def downsample(points, config=None, viewpoint=None):
    """Downsamples one point cloud to an additive Poisson-disk hierarchy.

    points: a structured array with fields x, y, z (read_cloud's: cloud[s["index"]] are then the samples with
        every field), or an (N, 3) NumPy array of float32 or float64 (float64 is sampled at full precision, as `hpds sample` samples
        a file with float64 x y z: georeferenced coordinates keep their guarantees), in the sensor frame (metres;
        normals face the origin, or `viewpoint`). NaN/Inf points, exact (0,0,0) no-returns and points outside
        input.min_range/max_range are skipped.
    config: None (the defaults), a dict in config/hpds.yaml's layout (missing keys keep their defaults), or the path
        of a YAML file in that layout.
    viewpoint: None (the origin) or the sensor position (x, y, z) in the points' frame, which normals face: a PCD's
        VIEWPOINT, from read_points(path, return_viewpoint=True). Must be finite (ValueError otherwise).
    Returns a dict of NumPy arrays, one entry per sample: "index" (uint32, position in `points`), "level" (uint8,
        0..D of the output level D) and, with normals.enabled, "normal" ((n, 3) float32, facing the sensor; NaN where
        no normal could be estimated) and "curvature" (float32); with normals.covariances also "covariance"
        ((n, 3, 3) float32: the sample's covariance for generalized ICP; the identity where no plane is known, the
        normal's NaN samples included: every one can go to GICP as it is).
        The dict is a Samples: its `skipped` attribute counts the input points left out, by reason. Points beyond
        the exact key range of the finest level (|coordinate| of about 1.5e7 m at the defaults: georeferenced
        coordinates) are left out too; when there are any, a RuntimeWarning says how many. So does one when map mode
        gives samples up to stay within map.max_samples, and one when float32 points are rounded by more than 1 % of
        the output radius (georeferenced coordinates: pass float64, or coordinates relative to a local origin).
    Raises ValueError naming the key for an invalid config, TypeError for a points array of another type. Ctrl-C
    (any signal handler that raises) stops the call within about a second, on millions of points too.
    """
    text, path = _config_source(config)
    if viewpoint is None:
        viewpoint = (0.0, 0.0, 0.0)
    try:
        viewpoint = [float(v) for v in viewpoint]
    except (TypeError, ValueError):
        raise ValueError("viewpoint: expected 3 numbers (x, y, z), got %r" % (viewpoint,)) from None
    xyz = _xyz_of(points)
    arrays, skipped, rounding, resolution, far = _hpds.downsample(xyz, text, path, viewpoint)
    result = Samples(arrays)
    result.skipped = skipped
    result.resolution = resolution
    if skipped["out_of_range"]:
        warnings.warn("hpds.downsample: %d points lie beyond the exact key range and were not sampled (see "
                      "samples.skipped): %s" % (skipped["out_of_range"], _hpds.key_range_advice(text, path)),
                      RuntimeWarning, stacklevel=2)
    if skipped["evicted"]:
        warnings.warn("hpds.downsample: map mode gave up %d samples, the farthest from the viewpoint, to stay within "
                      "map.max_samples (see samples.skipped): the result no longer covers the cloud; raise "
                      "map.max_samples (0 = no cap), or use mode: scan for one cloud" % skipped["evicted"],
                      RuntimeWarning, stacklevel=2)
    if rounding:
        warnings.warn("hpds.downsample: " + rounding, RuntimeWarning, stacklevel=2)
    if far:
        # As `hpds sample` warns: world coordinates given without the sensor's position orient the normals toward a
        # point a kilometre or more away, about half of them the wrong way, and range limits measure from it.
        warnings.warn("hpds.downsample: the nearest point is %.1f m from the viewpoint (%g, %g, %g), where normals are "
                      "made to face and input.min_range/max_range measure from: the points seem not to be in their "
                      "sensor's frame; pass the sensor's position as viewpoint=(x, y, z)" % ((far,) + tuple(viewpoint)),
                      RuntimeWarning, stacklevel=2)
    return result


def load_config(config=None):
    """The sampling keys of a config (None, dict or YAML path, as for downsample), validated, as a dict of sections:
    every key downsample reads (mode, hierarchy, output, ...). The node's `ros` section and `diagnostic_period` are
    validated too but not returned: no Python call uses them."""
    text, path = _config_source(config)
    return _hpds.config_dict(text, path)


def read_points(path, return_viewpoint=False):
    """x, y, z of a .pcd, .ply (built with PCL) or KITTI .bin file as an (N, 3) float64 array.

    With return_viewpoint, a tuple (points, viewpoint): the sensor position a PCD's VIEWPOINT gives ((3,) float64;
    zeros for other formats or without one), which downsample(points, config, viewpoint) turns the normals toward,
    as `hpds sample` does. Raises FileNotFoundError / IsADirectoryError for a path that is no file, RuntimeError
    naming the file for one that cannot be read."""
    path = os.fspath(path)
    _refuse_unreadable(path, "point cloud file")
    return _hpds.read_points(path, bool(return_viewpoint))


def read_cloud(path, return_viewpoint=False):
    """Every point of a .pcd, .ply (built with PCL) or KITTI .bin file with all its fields (x, y, z, intensity, ring,
    time, ...) as a NumPy structured array, the records as stored (little-endian; PCL's packed rgb as a uint32).

        cloud = hpds.read_cloud("frame.pcd")
        s = hpds.downsample(cloud)
        samples = cloud[s["index"]]                 # every field of the sampled points

    An organized cloud comes flat (row by row), its no-return points included (downsample skips them). With
    return_viewpoint, a tuple (cloud, viewpoint) as for read_points. Raises as read_points does."""
    path = os.fspath(path)
    _refuse_unreadable(path, "point cloud file")
    return _hpds.read_cloud(path, bool(return_viewpoint))


def read_poses(path):
    """A pose file (KITTI: one 3x4 sensor-to-world matrix per line; or TUM: time x y z qx qy qz qw) as an
    (N, 4, 4) float64 array.

    A KITTI rotation that is not orthonormal to double precision is replaced by the nearest true rotation; beyond
    what printing rounds (it would move a point 100 m out by more than 1 mm) a RuntimeWarning says so.

    Raises FileNotFoundError / IsADirectoryError for a path that is no file, RuntimeError for a malformed one."""
    path = os.fspath(path)
    _refuse_unreadable(path, "pose file")
    poses, corrected = _hpds.read_poses(path)
    if corrected:
        warnings.warn("hpds.read_poses: " + corrected, RuntimeWarning, stacklevel=2)
    return poses
