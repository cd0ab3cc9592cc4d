"""The workers' cache of shipped binaries: one no task used for a day goes when a new one
arrives; the one in use and the recently used stay (no cluster needed)."""

import os
import sys
import tempfile
import time
import unittest

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from blendsim_ray.worker import UNUSED_SECONDS, remove_unused_binaries  # noqa: E402


class BinaryCache(unittest.TestCase):
    def test_a_binary_unused_for_a_day_is_removed_the_others_stay(self):
        with tempfile.TemporaryDirectory() as bin_dir:
            now = time.time()
            ages = {"new": 0, "recent": UNUSED_SECONDS - 60, "old": UNUSED_SECONDS + 60, "kept-old": UNUSED_SECONDS + 60}
            for sha, age in ages.items():
                folder = os.path.join(bin_dir, sha)
                os.makedirs(folder)
                with open(os.path.join(folder, "blendsim"), "wb") as f:
                    f.write(b"\x7fELF")
                os.utime(folder, (now - age, now - age))
            remove_unused_binaries(bin_dir, keep="kept-old", now=now)
            self.assertEqual(sorted(os.listdir(bin_dir)), ["kept-old", "new", "recent"])


if __name__ == "__main__":
    unittest.main()
