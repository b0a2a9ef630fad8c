#!/usr/bin/env python3
"""Unit tests of the fault-replay harness itself (the edits and the evaluation), on small synthetic
files, so that a FAIL row in run_faults.py's table is the localizer's and not the harness's."""
import os
import sys
import tempfile
import unittest

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import run_faults as rf  # noqa: E402

MS = 1_000_000


def frames(ts):
    return [f"{t},frames/{i:06d}.png" for i, t in enumerate(ts)]


def write_truth(d, rows):
    rf.write_rows(os.path.join(d, "truth.csv"), "t_ns,x_mm,y_mm,theta_deg",
                  [f"{t},{x},{y},{th}" for t, x, y, th in rows])


class Edits(unittest.TestCase):
    def test_remove_window_is_open_interval(self):
        lines = frames(range(0, 100 * MS, 10 * MS))
        out = rf.remove_window(20 * MS, 50 * MS)(lines)
        self.assertEqual([rf.t_of(x) for x in out], [0, 10 * MS, 20 * MS, 50 * MS, 60 * MS,
                                                      70 * MS, 80 * MS, 90 * MS])

    def test_forward_jump_drops_overtaken_frames_after_window(self):
        lines = frames(range(0, 1000 * MS, 50 * MS))  # 0..950 ms at 20 fps
        out = rf.shift_window(200 * MS, 400 * MS, 300 * MS)(lines)
        ts = [rf.t_of(x) for x in out]
        self.assertTrue(all(a < b for a, b in zip(ts, ts[1:])))
        names = {x.split(",")[1]: rf.t_of(x) for x in out}
        self.assertEqual(names["frames/000004.png"], 500 * MS)  # 200 ms + 300 ms
        self.assertEqual(names["frames/000007.png"], 650 * MS)  # last one in the window
        for i in (8, 9, 10, 11, 12, 13):  # 400..650 ms would not be after 650 ms
            self.assertNotIn(f"frames/{i:06d}.png", names)
        self.assertEqual(names["frames/000014.png"], 700 * MS)
        self.assertEqual(names["frames/000003.png"], 150 * MS)

    def test_backward_jump_drops_frames_before_window(self):
        lines = frames(range(0, 1000 * MS, 50 * MS))
        out = rf.shift_window(500 * MS, 700 * MS, -300 * MS)(lines)
        ts = [rf.t_of(x) for x in out]
        self.assertTrue(all(a < b for a, b in zip(ts, ts[1:])))
        names = {x.split(",")[1]: rf.t_of(x) for x in out}
        self.assertEqual(names["frames/000010.png"], 200 * MS)
        for i in (4, 5, 6, 7, 8, 9):  # 200..450 ms are not before the shifted 200 ms
            self.assertNotIn(f"frames/{i:06d}.png", names)
        self.assertEqual(names["frames/000003.png"], 150 * MS)
        self.assertEqual(names["frames/000014.png"], 700 * MS)


class TruthAndEvaluation(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.d = self.tmp.name

    def tearDown(self):
        self.tmp.cleanup()

    def test_interpolates_heading_across_wrap(self):
        write_truth(self.d, [(0, 0.0, 0.0, 179.0), (10 * MS, 10.0, 0.0, -179.0)])
        t = rf.Truth(os.path.join(self.d, "truth.csv"))
        x, _, th = t.at(5 * MS)
        self.assertAlmostEqual(x, 5.0)
        self.assertAlmostEqual((th + 180.0) % 360.0 - 180.0, -180.0, places=6)
        self.assertIsNone(t.at(11 * MS))

    def test_turns_and_straights_from_headings(self):
        # 0.1 s straight, 0.1 s turning at 1 rad/s, straight again.
        rows, th = [], 0.0
        for k in range(31):
            rows.append((k * 10 * MS, 0.0, 0.0, th))
            if 10 <= k < 20:
                th += 0.01 * 57.29577951308232
        write_truth(self.d, rows)
        t = rf.Truth(os.path.join(self.d, "truth.csv"))
        segs = t.motion_segments([r[0] for r in rows])
        self.assertEqual([s[2] for s in segs], ["straight", "turn", "straight"])
        self.assertEqual((segs[1][0], segs[1][1]), (100 * MS, 200 * MS))

    def evaluate(self, poses, fixes, start, end):
        write_truth(self.d, [(0, 0.0, 0.0, 0.0), (10_000 * MS, 0.0, 0.0, 0.0)])
        out = os.path.join(self.d, "out")
        os.makedirs(out, exist_ok=True)
        rf.write_rows(os.path.join(out, "poses.csv"),
                      "t_ns,valid,health,x_mm,y_mm,theta_deg,sigma_x_mm,sigma_y_mm,"
                      "sigma_theta_deg,time_since_fix_ms", poses)
        rf.write_rows(os.path.join(out, "fixes.csv"), "t_ns,status,landmark_id", fixes)
        v = rf.Variant("x", self.d, start, end, "")
        v.out = out
        return rf.evaluate(v, rf.Truth(os.path.join(self.d, "truth.csv")))

    def test_assertions(self):
        # 100 ticks at 10 ms: localized and 1 mm off with sigma 1 mm (coverage ok, RMS 0.58),
        # except ticks 20..39 dead reckoning 60 mm off (not localized: allowed, but outside 3 sigma)
        poses = []
        for k in range(100):
            off, health = (60.0, 2) if 20 <= k < 40 else (1.0, 1)
            poses.append(f"{k * 10 * MS},1,{health},{off},0,0,1,1,1,0")
        r = self.evaluate(poses, [f"{420 * MS},ok,3"], 0, 400 * MS)
        self.assertEqual(r["max_loc_mm"], 1.0)
        self.assertAlmostEqual(r["coverage"], 0.8)
        self.assertFalse(r["pass"])
        self.assertEqual(r["recovery"][1], 0.0)  # tick 40 is good again
        self.assertTrue(r["recovery"][2])  # ok fix 20 ms after the end

        # Recovery 0.6 s with a landmark in view: fails; without one in view: not asserted.
        poses = [f"{k * 10 * MS},1,{2 if k < 60 else 1},1,0,0,1,1,1,0" for k in range(100)]
        r = self.evaluate(poses, [f"{100 * MS},ok,3"], 0, 0)
        self.assertAlmostEqual(r["recovery"][1], 0.6)
        self.assertTrue(any("recovery" in e for e in r["errors"]))
        r = self.evaluate(poses, [f"{550 * MS},ok,3"], 0, 0)
        self.assertFalse(r["recovery"][2])
        # Exposed 0.48 s after the end: its fix cannot be fused within 0.5 s (FIX_DELAY_S).
        self.assertFalse(self.evaluate(poses, [f"{480 * MS},ok,3"], 0, 0)["recovery"][2])
        self.assertTrue(self.evaluate(poses, [f"{460 * MS},ok,3"], 0, 0)["recovery"][2])
        self.assertAlmostEqual(r["recovery"][3], 0.05)
        self.assertTrue(r["pass"], r["errors"])

        # Sigma 10x too large: RMS 0.06 < 0.2.
        poses = [f"{k * 10 * MS},1,1,1,0,0,10,10,10,0" for k in range(100)]
        r = self.evaluate(poses, [], None, None)
        self.assertLess(r["nees_rms"], rf.NEES_RMS_MIN)
        self.assertFalse(r["pass"])

        # A localized tick 51 mm off fails.
        poses = [f"{k * 10 * MS},1,1,{51 if k == 50 else 1},0,0,30,30,30,0" for k in range(100)]
        r = self.evaluate(poses, [], None, None)
        self.assertTrue(any("localized ticks" in e for e in r["errors"]))


class BaseFrom(unittest.TestCase):
    """A sanitizer build takes the default build's base recordings only when they were rendered
    with the same simulator arguments; otherwise it renders its own."""

    def _rendered(self, root, args_line):
        d = os.path.join(root, "base")
        os.makedirs(os.path.join(d, "frames"))
        for name in ("meta.yaml", "frames.csv", "frames/000000.png"):
            with open(os.path.join(d, name), "w") as f:
                f.write(name)
        with open(os.path.join(d, "render.args"), "w") as f:
            f.write(args_line)
        return d

    def test_same_arguments_are_taken(self):
        with tempfile.TemporaryDirectory() as src, tempfile.TemporaryDirectory() as dst:
            self._rendered(src, "--duration-s 40 --seed 1\n")
            out = os.path.join(dst, "base")
            self.assertTrue(rf.copy_rendered(os.path.join(src, "base"), out,
                                             "--duration-s 40 --seed 1\n"))
            with open(os.path.join(out, "frames", "000000.png")) as f:
                self.assertEqual(f.read(), "frames/000000.png")

    def test_other_arguments_or_no_stamp_are_not_taken(self):
        with tempfile.TemporaryDirectory() as src, tempfile.TemporaryDirectory() as dst:
            d = self._rendered(src, "--duration-s 40 --seed 1\n")
            out = os.path.join(dst, "base")
            self.assertFalse(rf.copy_rendered(d, out, "--duration-s 40 --seed 2\n"))
            self.assertFalse(os.path.exists(out))
            os.remove(os.path.join(d, "render.args"))
            self.assertFalse(rf.copy_rendered(d, out, "--duration-s 40 --seed 1\n"))
            self.assertFalse(rf.copy_rendered(os.path.join(src, "none"), out, "x\n"))


if __name__ == "__main__":
    unittest.main()
