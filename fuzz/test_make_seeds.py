#!/usr/bin/env python3
"""make_seeds.py regenerates its seeds and keeps every other corpus input (ctest fuzz_make_seeds).

Regression: the script used to delete fuzz/corpus/ before writing the seeds, so a rerun dropped
the committed minimised inputs (fuzz_vision's hashes, regress_*) without a word."""
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

FUZZ = os.path.dirname(os.path.abspath(__file__))
SCRIPT = os.path.join(FUZZ, "make_seeds.py")


def files_under(d):
    out = {}
    for root, _, names in os.walk(d):
        for n in names:
            p = os.path.join(root, n)
            with open(p, "rb") as f:
                out[os.path.relpath(p, d)] = f.read()
    return out


class MakeSeeds(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp()
        self.corpus = os.path.join(self.tmp, "corpus")
        shutil.copytree(os.path.join(FUZZ, "corpus"), self.corpus)

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def run_script(self):
        r = subprocess.run([sys.executable, SCRIPT, self.corpus], capture_output=True, text=True)
        self.assertEqual(r.returncode, 0, r.stderr)
        return r.stdout

    def test_committed_inputs_the_script_does_not_own_survive(self):
        before = files_under(self.corpus)
        with open(os.path.join(self.corpus, "seeds.manifest")) as f:
            owned = {l.strip() for l in f if l.strip() and not l.startswith("#")}
        kept = {p for p in before if p != "seeds.manifest" and p not in owned}
        self.assertTrue(any(p.startswith("fuzz_vision/") for p in kept),
                        "the committed corpus should hold minimised inputs besides the seeds")
        self.run_script()
        after = files_under(self.corpus)
        for p in kept:
            self.assertIn(p, after, f"{p} was removed")
            self.assertEqual(after[p], before[p], f"{p} was changed")
        for p in owned:
            self.assertIn(p, after, f"the seed {p} was not written")

    def test_a_seed_no_longer_written_is_removed_and_nothing_outside_is(self):
        self.run_script()
        stale = os.path.join(self.corpus, "fuzz_payload", "seed_dropped")
        found = os.path.join(self.corpus, "fuzz_vision", "minimised_by_hand")
        outside = os.path.join(self.tmp, "outside")
        for p in (stale, found, outside):
            with open(p, "w") as f:
                f.write("x")
        with open(os.path.join(self.corpus, "seeds.manifest"), "a") as f:
            f.write("fuzz_payload/seed_dropped\n../outside\nfuzz_payload/../../outside\n")
        out = self.run_script()
        self.assertFalse(os.path.exists(stale), out)
        self.assertIn("removed the stale seed fuzz_payload/seed_dropped", out)
        self.assertTrue(os.path.exists(found))
        self.assertTrue(os.path.exists(outside), "a hand-edited manifest reached outside the corpus")
        with open(os.path.join(self.corpus, "seeds.manifest")) as f:
            self.assertNotIn("seed_dropped", f.read())

    def test_a_second_run_changes_nothing(self):
        self.run_script()
        first = files_under(self.corpus)
        self.run_script()
        self.assertEqual(files_under(self.corpus), first)


if __name__ == "__main__":
    unittest.main()
