"""Binary little-endian PLY files as NumPy structured arrays: reading hpds's outputs (the tiles of a tiled map build,
`hpds sample`'s files), merging tiles, writing a cloud atomically.

    tile = hpds.ply.read("out/tile_0_1.ply")        # fields x, y, z, level, [normal_x ... curvature], input fields
    hpds.ply.merge(["out/tile_0_1.ply", "out/tile_1_1.ply"], "map.ply")
"""
import os

import numpy as np

_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2",
          "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
          "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8"}
_NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint", "f4": "float",
          "f8": "double"}


def read(path):
    """The vertices of a binary little-endian PLY file as a structured array (one field per property)."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise ValueError("%s: not a PLY file" % path)
        fields, count, fmt, in_vertex = [], None, None, False
        while True:
            line = f.readline()
            if not line:
                raise ValueError("%s: header ends before end_header" % path)
            words = line.decode("ascii", "replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "element":
                in_vertex = words[1] == "vertex"
                if in_vertex:
                    count = int(words[2])
                elif fields or count is None:
                    raise ValueError("%s: only files whose first element is vertex are read" % path)
            elif words[0] == "property" and in_vertex:
                if words[1] == "list" or words[1] not in _TYPES:
                    raise ValueError("%s: unsupported property '%s'" % (path, " ".join(words[1:])))
                fields.append((words[2], _TYPES[words[1]]))
        if fmt != "binary_little_endian" or count is None:
            raise ValueError("%s: only binary_little_endian PLY with a vertex element is read" % path)
        dtype = np.dtype(fields)
        data = np.frombuffer(f.read(dtype.itemsize * count), dtype=dtype)
        if len(data) != count:
            raise ValueError("%s: truncated (%d of %d vertices)" % (path, len(data), count))
        return data.copy()


def write(path, vertices):
    """Writes a structured array as binary little-endian PLY, atomically (a temporary beside `path`, renamed)."""
    vertices = np.ascontiguousarray(vertices)
    lines = ["ply", "format binary_little_endian 1.0", "element vertex %d" % len(vertices)]
    for name in vertices.dtype.names:
        base = vertices.dtype[name].base
        if vertices.dtype[name].shape:
            raise ValueError("write: field '%s' is not a scalar" % name)
        lines.append("property %s %s" % (_NAMES[base.str.lstrip("<>|=")], name))
    lines.append("end_header")
    le = np.dtype([(n, vertices.dtype[n].newbyteorder("<")) for n in vertices.dtype.names])
    tmp = "%s.tmp.%d" % (path, os.getpid())
    try:
        with open(tmp, "wb") as f:
            f.write(("\n".join(lines) + "\n").encode("ascii"))
            f.write(vertices.astype(le).tobytes())
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def merge(paths, out_path):
    """Concatenates PLY files with the same fields (the tiles of one build) into one, written atomically."""
    if os.path.abspath(out_path) in {os.path.abspath(p) for p in paths}:
        raise ValueError("merge: the output '%s' is one of the inputs" % out_path)
    parts = [read(p) for p in paths]
    for p, part in zip(paths[1:], parts[1:]):
        if part.dtype != parts[0].dtype:
            raise ValueError("merge: '%s' has other fields than '%s'" % (p, paths[0]))
    write(out_path, np.concatenate(parts) if parts else np.zeros(0, [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]))
