#!/usr/bin/env python3
"""Unit test of mqtt_replay.py's comparison of the published positions with poses.csv (no broker)."""
import math
import os
import sys
import tempfile
import unittest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import mqtt_replay  # noqa: E402

HEAD = "t_ns,valid,health,x_mm,y_mm,theta_deg\n"


class PosesByMs(unittest.TestCase):
    def test_two_ticks_in_one_millisecond_are_both_kept_and_either_matches(self):
        # A late tick and the next on schedule 0.38 ms apart (the CI run that failed), 0.5 m/s.
        rows = ["16146411750,1,1,2322.9467,20.0291,0.00509\n",
                "16146793637,1,1,2323.1363,20.0291,0.00500\n",
                "16156000000,1,1,2327.7000,20.0291,0.00500\n"]
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "poses.csv")
            with open(path, "w") as f:
                f.write(HEAD + "".join(rows))
            poses = mqtt_replay.poses_by_ms(path)
        self.assertEqual(sorted(poses), [16146, 16156])
        self.assertEqual(len(poses[16146]), 2)
        for x_mm, theta_deg in ((2322.9467, 0.00509), (2323.1363, 0.00500)):
            p = {"x": x_mm / 1000, "y": 0.0200291, "theta": math.radians(theta_deg)}
            r, (dx, dy, dth) = mqtt_replay.closest_row(poses[16146], p)
            self.assertEqual(float(r["x_mm"]), x_mm)
            self.assertLess(max(dx, dy), 1e-4)
            self.assertLess(dth, 1e-5)

    def test_a_position_off_by_a_tenth_of_a_millimetre_is_reported(self):
        rows = [{"x_mm": "1000.0000", "y_mm": "0.0000", "theta_deg": "0.00000"}]
        _, (dx, dy, _) = mqtt_replay.closest_row(rows, {"x": 1.0002, "y": 0.0, "theta": 0.0})
        self.assertGreater(dx, 1e-4)
        self.assertLess(dy, 1e-9)


if __name__ == "__main__":
    unittest.main()
