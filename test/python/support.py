"""Shared helpers of the Python tests: where the built tools and the shared lidar frames are, scratch folders."""
import os
import shutil
import subprocess
import tempfile
import unittest

import numpy as np

CLI = os.environ.get("HPDS_CLI", "")
DOWNSAMPLE_DUMP = os.environ.get("HPDS_DOWNSAMPLE_DUMP", "")
SHARED_DATA = os.environ.get("HPDS_SHARED_DATA_DIR", "")


def shared_frames():
    """The real frames of ../shared/data/lidar, or [] when the folder is absent (a user's clone has none)."""
    if not SHARED_DATA or not os.path.isdir(SHARED_DATA):
        return []
    return sorted(os.path.join(SHARED_DATA, f) for f in os.listdir(SHARED_DATA) if f.endswith(".pcd"))


def require_tools(case):
    if not CLI or not DOWNSAMPLE_DUMP:
        case.skipTest("HPDS_CLI / HPDS_DOWNSAMPLE_DUMP not set: run through ctest")


class ScratchCase(unittest.TestCase):
    """A test case with a fresh scratch folder per test, removed afterwards."""

    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="hpds_py_")
        self.addCleanup(shutil.rmtree, self.tmp, True)

    def path(self, name):
        return os.path.join(self.tmp, name)


def run(args, check=True):
    """Runs a command, returns (exit status, stdout + stderr)."""
    p = subprocess.run(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if check and p.returncode != 0:
        raise AssertionError("%s failed (%d):\n%s" % (" ".join(args), p.returncode, p.stdout))
    return p.returncode, p.stdout


def write_kitti_bin(path, xyz):
    """KITTI .bin: float32 x y z intensity per point (intensity 0)."""
    rec = np.zeros((len(xyz), 4), np.float32)
    rec[:, :3] = xyz
    rec.tofile(path)


def read_dump(path):
    """The arrays downsample_dump wrote (see downsample_dump.cpp)."""
    raw = np.fromfile(path, np.uint8)
    n = int(raw[:8].view(np.uint64)[0])
    has_normals = bool(raw[8])
    pos = 9
    out = {"index": raw[pos:pos + 4 * n].view(np.uint32)}
    pos += 4 * n
    out["level"] = raw[pos:pos + n].copy()
    pos += n
    if has_normals:
        out["normal"] = raw[pos:pos + 12 * n].view(np.float32).reshape(n, 3)
        pos += 12 * n
        out["curvature"] = raw[pos:pos + 4 * n].view(np.float32)
        pos += 4 * n
    assert pos == len(raw), "dump size"
    return out
