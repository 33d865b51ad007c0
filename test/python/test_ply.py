"""hpds.ply on hostile files and arrays: every bad header is a ValueError naming the file (no IndexError, MemoryError
or numpy message without it), a mesh's vertices are read, write refuses what PLY cannot hold instead of writing a
broken header, and merge never writes over an input, whatever path names it."""
import os

import numpy as np

import hpds.ply
import support

HEAD = "ply\nformat binary_little_endian 1.0\n"


def cloud(n=4):
    a = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "u1")])
    a["x"] = np.arange(n)
    a["y"] = 2 * np.arange(n)
    a["intensity"] = 7
    return a


class Read(support.ScratchCase):
    def file(self, name, text, body=b""):
        path = self.path(name)
        with open(path, "wb") as f:
            f.write(text.encode("ascii") + body)
        return path

    def assert_refused(self, name, header, *parts, body=b""):
        path = self.file(name, header, body)
        with self.assertRaises(ValueError) as e:
            hpds.ply.read(path)
        self.assertIn(path, str(e.exception))
        for p in parts:
            self.assertIn(p, str(e.exception))

    def test_round_trip_keeps_every_field(self):
        a = cloud()
        hpds.ply.write(self.path("a.ply"), a)
        b = hpds.ply.read(self.path("a.ply"))
        self.assertEqual(b.dtype.names, a.dtype.names)
        self.assertTrue(np.array_equal(b, a))

    def test_bad_headers_name_the_file(self):
        body = b"\0" * 12
        self.assert_refused("no_count.ply", HEAD + "element vertex\nproperty float x\nend_header\n", "element")
        self.assert_refused("negative.ply", HEAD + "element vertex -1\nproperty float x\nend_header\n", "count >= 0")
        self.assert_refused("word.ply", HEAD + "element vertex abc\nproperty float x\nend_header\n", "count >= 0")
        self.assert_refused("float_count.ply", HEAD + "element vertex 1e20\nproperty float x\nend_header\n", "count")
        # Far more than the file holds: refused before anything is allocated.
        self.assert_refused("huge.ply", HEAD + "element vertex 1000000000000000\nproperty float x\nend_header\n",
                            "truncated", body=body)
        self.assert_refused("short_format.ply", "ply\nformat\nelement vertex 1\nproperty float x\nend_header\n",
                            "format")
        self.assert_refused("short_property.ply", HEAD + "element vertex 1\nproperty float\nend_header\n", "property")
        self.assert_refused("no_properties.ply", HEAD + "element vertex 1\nend_header\n", "no properties", body=body)
        self.assert_refused("twice.ply", HEAD + "element vertex 1\nproperty float x\nproperty float x\nend_header\n",
                            "appears twice", body=body)
        self.assert_refused("face_first.ply", HEAD + "element face 1\nproperty list uchar int vertex_indices\n"
                            "element vertex 1\nproperty float x\nend_header\n", "before the vertex element")
        self.assert_refused("keyword.ply", HEAD + "element vertex 1\nproperty float x\nbogus 3\nend_header\n",
                            "unknown keyword")
        self.assert_refused("ascii.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n",
                            "binary_little_endian")

    def test_a_mesh_gives_its_vertices(self):
        # Vertex first, then faces: the faces' data follows the vertices and is not read.
        a = cloud(3)
        header = (HEAD + "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "property uchar intensity\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n")
        face = bytes([3]) + np.array([0, 1, 2], "<i4").tobytes()
        path = self.file("mesh.ply", header, a.tobytes() + face)
        self.assertTrue(np.array_equal(hpds.ply.read(path), a))


class Write(support.ScratchCase):
    def test_names_that_would_break_the_header_are_refused(self):
        for name in ("y\nend_header", "return type", "\u00e9"):
            with self.subTest(name=name):
                a = np.zeros(2, dtype=[("x", "<f4"), (name, "<f4")])
                with self.assertRaises(ValueError) as e:
                    hpds.ply.write(self.path("n.ply"), a)
                self.assertIn("field name", str(e.exception))
                self.assertFalse(os.path.exists(self.path("n.ply")))

    def test_types_plys_cannot_hold_are_refused_with_what_to_use(self):
        for dtype, hint in (("<i8", "int32"), ("<u8", "uint32"), ("?", "uint8"), ("<f2", "")):
            with self.subTest(dtype=dtype):
                a = np.zeros(2, dtype=[("x", "<f4"), ("v", dtype)])
                with self.assertRaises(ValueError) as e:
                    hpds.ply.write(self.path("t.ply"), a)
                self.assertIn("'v'", str(e.exception))
                self.assertIn(hint, str(e.exception))

    def test_a_plain_array_is_refused(self):
        with self.assertRaises(ValueError) as e:
            hpds.ply.write(self.path("p.ply"), np.zeros((5, 3), np.float32))
        self.assertIn("structured array", str(e.exception))

    def test_big_endian_fields_are_written_little_endian(self):
        a = cloud().astype([("x", ">f4"), ("y", ">f4"), ("z", ">f4"), ("intensity", "u1")])
        hpds.ply.write(self.path("be.ply"), a)
        self.assertTrue(np.array_equal(hpds.ply.read(self.path("be.ply"))["y"], cloud()["y"]))


class Merge(support.ScratchCase):
    def setUp(self):
        super().setUp()
        os.makedirs(self.path("md"))
        hpds.ply.write(self.path("md/a.ply"), cloud(3))
        hpds.ply.write(self.path("md/b.ply"), cloud(5))
        self.inputs = [self.path("md/a.ply"), self.path("md/b.ply")]
        self.before = [self.bytes_of(p) for p in self.inputs]

    @staticmethod
    def bytes_of(path):
        with open(path, "rb") as f:
            return f.read()

    def assert_inputs_untouched(self):
        self.assertEqual([self.bytes_of(p) for p in self.inputs], self.before)

    def test_merge_takes_any_iterable_or_one_path_and_names_a_missing_folder(self):
        # A generator failed ('not subscriptable'), one path as a string was read character by character, and a
        # missing output folder was named by the temporary's name.
        hpds.ply.merge((p for p in self.inputs), self.path("gen.ply"))
        hpds.ply.merge(self.inputs[0], self.path("one.ply"))
        self.assertEqual(len(hpds.ply.read(self.path("one.ply"))), len(hpds.ply.read(self.inputs[0])))
        self.assertEqual(len(hpds.ply.read(self.path("gen.ply"))), sum(len(hpds.ply.read(p)) for p in self.inputs))
        with self.assertRaises(FileNotFoundError) as e:
            hpds.ply.merge(self.inputs, self.path(os.path.join("nodir", "x.ply")))
        self.assertIn("nodir", str(e.exception))
        self.assertNotIn(".tmp.", str(e.exception))

    def test_an_empty_list_or_another_formats_name_is_refused(self):
        # merge([]) wrote an empty PLY (a build of no points, to whoever reads it), and a .pcd name got PLY bytes.
        with self.assertRaises(ValueError) as e:
            hpds.ply.merge([], self.path("none.ply"))
        self.assertIn("no input files", str(e.exception))
        self.assertFalse(os.path.exists(self.path("none.ply")))
        for name in ("all.pcd", "all.bin", "all"):
            with self.assertRaises(ValueError) as e:
                hpds.ply.merge(self.inputs, self.path(name))
            self.assertIn("not a .ply name", str(e.exception))
            self.assertFalse(os.path.exists(self.path(name)))
        hpds.ply.merge(self.inputs, self.path("upper.PLY"))
        self.assert_inputs_untouched()

    def test_a_file_given_twice_is_refused(self):
        # Found in a user trial: merge([t, t]) wrote every sample of t twice, two samples at distance 0.
        link = self.path("again.ply")
        os.symlink(self.inputs[0], link)
        for twice in ([self.inputs[0], self.inputs[1], self.inputs[0]], [self.inputs[0], link]):
            with self.assertRaises(ValueError) as e:
                hpds.ply.merge(twice, self.path("twice.ply"))
            self.assertIn("is given twice", str(e.exception))
            self.assertFalse(os.path.exists(self.path("twice.ply")))
        self.assert_inputs_untouched()

    def test_merges(self):
        hpds.ply.merge(self.inputs, self.path("all.ply"))
        self.assertEqual(len(hpds.ply.read(self.path("all.ply"))), 8)
        self.assertIsNone(hpds.ply.read_sampling_record(self.path("all.ply")))
        self.assert_inputs_untouched()

    def test_a_sampling_record_is_written_read_back_and_kept_by_a_merge_of_equal_ones(self):
        cell = 0.1 * 32 / (0.5 * np.sqrt(3.0))  # a derived cell: not a short decimal
        for name in ("r1.ply", "r2.ply"):
            hpds.ply.write(self.path(name), cloud(), record=(cell, 6, 5))
        self.assertEqual(hpds.ply.read_sampling_record(self.path("r1.ply")), (cell, 6, 5))
        self.assertTrue(hpds._hpds.ply_marked_as_samples(self.path("r1.ply")))
        self.assertEqual(len(hpds.ply.read(self.path("r1.ply"))), 4)
        hpds.ply.merge([self.path("r1.ply"), self.path("r2.ply")], self.path("same.ply"))
        self.assertEqual(hpds.ply.read_sampling_record(self.path("same.ply")), (cell, 6, 5))
        # Samplings of other cells merged are no longer one sampling: no record is carried.
        hpds.ply.write(self.path("r3.ply"), cloud(), record=(2 * cell, 6, 5))
        hpds.ply.merge([self.path("r1.ply"), self.path("r3.ply")], self.path("mixed.ply"))
        self.assertIsNone(hpds.ply.read_sampling_record(self.path("mixed.ply")))
        self.assertTrue(hpds._hpds.ply_marked_as_samples(self.path("mixed.ply")))
        # A record no reader would take is not written; one in a file is refused naming the file.
        with self.assertRaises(ValueError) as e:
            hpds.ply.write(self.path("bad.ply"), cloud(), record=(cell, 4, 5))
        self.assertIn("out of range", str(e.exception))
        self.assertFalse(os.path.exists(self.path("bad.ply")))
        with open(self.path("r1.ply"), "rb") as f:
            text = f.read().replace(b"max_depth 6 output_level 5", b"max_depth 4 output_level 5")
        with open(self.path("bad.ply"), "wb") as f:
            f.write(text)
        with self.assertRaises(RuntimeError) as e:
            hpds.ply.read_sampling_record(self.path("bad.ply"))
        self.assertIn("bad.ply", str(e.exception))
        self.assertIn("out of range", str(e.exception))

    def test_an_input_under_another_name_is_refused(self):
        os.symlink("md", self.path("linked_folder"))
        os.symlink(self.path("md/a.ply"), self.path("link.ply"))
        os.link(self.path("md/a.ply"), self.path("hard.ply"))
        for out in (self.path("md/a.ply"), self.path("linked_folder/a.ply"), self.path("link.ply"),
                    self.path("hard.ply"), self.path("md/../md/b.ply")):
            with self.subTest(out=out):
                with self.assertRaises(ValueError) as e:
                    hpds.ply.merge(self.inputs, out)
                self.assertIn("is the input", str(e.exception))
                self.assert_inputs_untouched()


if __name__ == "__main__":
    import unittest

    unittest.main()
