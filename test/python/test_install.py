"""`cmake --install` puts a working `hpds` package under the prefix: importable with PYTHONPATH set to
<prefix>/HPDS_PYTHON_INSTALL_DIR, linked to the installed libraries (not the build tree's)."""
import os
import subprocess
import sys
import unittest

import support


class Install(support.ScratchCase):
    def test_installed_package_imports_and_samples(self):
        build, cmake = os.environ.get("HPDS_BINARY_DIR"), os.environ.get("HPDS_CMAKE")
        if not build or not cmake:
            self.skipTest("HPDS_BINARY_DIR / HPDS_CMAKE not set: run through ctest")
        prefix = self.path("prefix")
        support.run([cmake, "--install", build, "--prefix", prefix])
        site = os.path.join(prefix, os.environ["HPDS_PYTHON_INSTALL_DIR"])
        self.assertTrue(os.path.isfile(os.path.join(site, "hpds", "__init__.py")))
        code = ("import hpds, numpy as np\n"
                "s = hpds.downsample(np.random.default_rng(1).uniform(-5, 5, (2000, 3)), {'output': {'level': 3}})\n"
                "assert len(s['index']) > 10, s\n"
                "print(hpds.__file__)\n")
        env = dict(os.environ, PYTHONPATH=site)
        # The build tree's libraries must not be what the installed module loads.
        env.pop("LD_LIBRARY_PATH", None)
        p = subprocess.run([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                           text=True, cwd=self.tmp)
        self.assertEqual(p.returncode, 0, p.stdout)
        self.assertTrue(p.stdout.strip().startswith(site), p.stdout)
        ldd = subprocess.run(["ldd"] + [os.path.join(site, "hpds", f) for f in os.listdir(os.path.join(site, "hpds"))
                                       if f.endswith(".so")], stdout=subprocess.PIPE, text=True).stdout
        core = [line for line in ldd.splitlines() if "libhpds_core" in line]
        self.assertTrue(core and all(prefix in line for line in core), ldd)


if __name__ == "__main__":
    unittest.main()
