"""Binary little-endian PLY files as NumPy structured arrays: reading hpds's outputs (the tiles of a tiled map build,
`hpds sample`'s files), merging tiles, writing a cloud atomically.

    tile = hpds.ply.read("out/tile_0_1.ply")        # fields x, y, z, level, [normal_x ... curvature], input fields
    hpds.ply.merge(["out/tile_0_1.ply", "out/tile_1_1.ply"], "map.ply")

Every problem with a file's contents is a ValueError that names it (a missing file or a folder is the OSError
open() raises); nothing is allocated beyond what the file holds.
"""
import errno
import os
import re

import numpy as np

from . import _hpds

_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "<i2", "int16": "<i2",
          "ushort": "<u2", "uint16": "<u2", "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
          "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8"}
_NAMES = {"i1": "char", "u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "u4": "uint", "f4": "float",
          "f8": "double"}
# A property name is one header word: printable ASCII without spaces (anything else would change the header).
_NAME = re.compile(r"^[!-~]+$")


def read(path):
    """The vertices of a binary little-endian PLY file as a structured array (one field per property). The vertex
    element must come first; elements after it (faces, say) are ignored."""
    def bad(why):
        return ValueError("%s: %s" % (path, why))

    with open(path, "rb") as f:
        if f.readline().strip() != b"ply":
            raise bad("not a PLY file")
        fields, count, fmt, element = [], None, None, None
        number = 1
        while True:
            line = f.readline()
            number += 1
            if not line:
                raise bad("header ends before end_header")
            words = line.decode("ascii", "replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            if words[0] == "format":
                if len(words) != 3:
                    raise bad("header line %d: expected 'format <type> <version>'" % number)
                fmt = words[1]
            elif words[0] == "element":
                if len(words) != 3 or not words[2].isdigit():
                    raise bad("header line %d: expected 'element <name> <count>' with a count >= 0" % number)
                element = words[1]
                if element == "vertex":
                    if count is not None:
                        raise bad("header line %d: a second vertex element" % number)
                    count = int(words[2])
                elif count is None:
                    raise bad("element '%s' comes before the vertex element; only files whose first element is "
                              "vertex are read" % element)
            elif words[0] == "property":
                if element != "vertex":
                    continue  # a later element's property: its data follows the vertices and is not read
                if len(words) < 3 or (words[1] != "list" and len(words) != 3):
                    raise bad("header line %d: expected 'property <type> <name>'" % number)
                if words[1] == "list" or words[1] not in _TYPES:
                    raise bad("unsupported property '%s'" % " ".join(words[1:]))
                if any(name == words[2] for name, _ in fields):
                    raise bad("property '%s' appears twice" % words[2])
                fields.append((words[2], _TYPES[words[1]]))
            else:
                raise bad("header line %d: unknown keyword '%s'" % (number, words[0][:40]))
        if fmt != "binary_little_endian" or count is None:
            raise bad("only binary_little_endian PLY with a vertex element is read")
        if not fields:
            raise bad("the vertex element has no properties")
        dtype = np.dtype(fields)
        available = os.fstat(f.fileno()).st_size - f.tell()
        if count * dtype.itemsize > available:
            raise bad("truncated: the header announces %d vertices of %d bytes, the file holds %d bytes after it"
                      % (count, dtype.itemsize, available))
        data = np.frombuffer(f.read(dtype.itemsize * count), dtype=dtype)
        return data.copy()


def read_sampling_record(path):
    """(cell_size, max_depth, output_level) that `hpds sample`, `hpds replay` or the map build recorded in the header
    of a sampling's PLY, or None for a file without one; RuntimeError naming the file when the line is malformed."""
    return _hpds.read_sampling_record(os.fspath(path))


def _property_type(vertices, name):
    base = vertices.dtype[name].base
    if vertices.dtype[name].shape:
        raise ValueError("write: field '%s' is not a scalar" % name)
    key = base.str.lstrip("<>|=")
    if key not in _NAMES:
        hint = {"b": " (use uint8)", "i": " (PLY has no 64-bit integers: use int32 or float64)",
                "u": " (PLY has no 64-bit integers: use uint32 or float64)"}.get(base.kind, "")
        raise ValueError("write: field '%s' has type %s, which PLY cannot store%s" % (name, base, hint))
    return _NAMES[key]


def write(path, vertices, samples=False, record=None):
    """Writes a structured array as binary little-endian PLY, atomically (a temporary beside `path`, renamed).

    samples: mark the file as a sampling's output, as `hpds sample` marks its own (its header comment), so that
    `hpds sample FOLDER` and the map build leave it out of a folder of frames; not for frames.
    record: (cell_size, max_depth, output_level) the sampling was made with, as read_sampling_record gives it:
    kept in the header (implies samples), so that `hpds verify` and `hpds analyze` need no --spacing."""
    if not os.fspath(path).lower().endswith(".ply"):
        # As `hpds sample -o out.pcd` is refused: a PLY under another format's name is read as that format.
        raise ValueError("write: '%s' is not a .ply name, and this writes PLY: name the output e.g. map.ply" % (path,))
    vertices = np.ascontiguousarray(vertices)
    if vertices.dtype.names is None or vertices.ndim != 1:
        raise ValueError("write: expects a 1-D structured array (fields x, y, z, ...), got shape %s and dtype %s"
                         % (vertices.shape, vertices.dtype))
    marks = [_hpds.PLY_SAMPLES_COMMENT] if samples or record is not None else []
    if record is not None:
        cell_size, max_depth, output_level = record
        marks.append(_hpds.sampling_record_line(float(cell_size), int(max_depth), int(output_level)))
    lines = ["ply", "format binary_little_endian 1.0"] + marks + ["element vertex %d" % len(vertices)]
    for name in vertices.dtype.names:
        if not _NAME.match(name):
            raise ValueError("write: field name %r is not one word of printable ASCII" % name)
        lines.append("property %s %s" % (_property_type(vertices, name), name))
    lines.append("end_header")
    le = np.dtype([(n, vertices.dtype[n].newbyteorder("<")) for n in vertices.dtype.names])
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        # Said by the path asked for, not by the temporary's name.
        raise FileNotFoundError("write: '%s' is in folder '%s', which does not exist" % (path, folder))
    tmp = "%s.tmp.%d" % (path, os.getpid())
    try:
        try:
            f = open(tmp, "wb")
        except PermissionError:
            # Said by the path asked for, not by the temporary's name.
            raise PermissionError(errno.EACCES, "write: '%s' is in folder '%s', which is not writable"
                                  % (path, folder)) from None
        with f:
            f.write(("\n".join(lines) + "\n").encode("ascii"))
            f.write(vertices.astype(le).tobytes())
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


def _same_file(a, b):
    """True when a and b name one file: the same path after links, or (both existing) the same inode."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def merge(paths, out_path):
    """Concatenates PLY files with the same fields (the tiles of one build) into one, written atomically.

    paths: an iterable of paths (a list, a generator, glob's result); a single path is taken as one file."""
    paths = [paths] if isinstance(paths, (str, bytes, os.PathLike)) else list(paths)
    if not paths:
        # An empty glob is a mistake upstream; an empty PLY in its place would pass for a build with no points.
        raise ValueError("merge: no input files (an empty list of paths): nothing written to '%s'" % (out_path,))
    seen = {}
    for p in paths:
        if _same_file(p, out_path):
            raise ValueError("merge: the output '%s' is the input '%s'" % (out_path, p))
        # A tile given twice would put every one of its samples into the output twice.
        try:
            st = os.stat(p)
            key = (st.st_dev, st.st_ino)
        except OSError:
            key = os.path.realpath(p)  # read() says what is wrong with it
        if key in seen:
            raise ValueError("merge: '%s' is given twice ('%s' is the same file): nothing written to '%s'"
                             % (p, seen[key], out_path))
        seen[key] = p
    parts = [read(p) for p in paths]
    for p, part in zip(paths[1:], parts[1:]):
        if part.dtype != parts[0].dtype:
            raise ValueError("merge: '%s' has other fields than '%s'" % (p, paths[0]))
    # The merged tiles of a build are a sampling's output as each tile is; anything else merged is not marked. The
    # tiles' sampling record is kept when they all carry the same one (one build's tiles do).
    records = {read_sampling_record(p) for p in paths}
    record = records.pop() if len(records) == 1 else None
    write(out_path, np.concatenate(parts), samples=all(_hpds.ply_marked_as_samples(os.fspath(p)) for p in paths),
          record=record)
