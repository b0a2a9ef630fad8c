#!/usr/bin/env python3
"""Unit tests of the HIL analysis on synthetic frames (no VM): a link flap may cut the one pose
pair it falls into, and nothing else may go unpaired; the bus poses are found in the localizer's
own record however many rows an outage skipped, and a pose it never wrote fails; the generated
configuration accepts late fixes; the offline reference gets no gyro the bus does not carry."""
import os
import sys
import unittest

sys.dont_write_bytecode = True  # no __pycache__ in the source tree
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import hil_dbc  # noqa: E402
from hil_analysis import (  # noqa: E402
    check_received_odometry, match_own, pair_pose_frames, pending_windows)
from hil_common import Frame, Report, Setup, prepare_config, quantize_recording  # noqa: E402

PERIOD = 0.02
WINDOW = 0.1


def frame(t, counter):
    return Frame(t=t, can_id=0x300, ext=False, data=bytes([0, counter & 0x0F, 0, 0, 0, 0, 0, 0]))


def bus(n, t0=0.0, drop_heading=(), skip=()):
    """n periods; the Heading of each period index in drop_heading is missing; the periods in
    skip send nothing (the link is down)."""
    xy, hd = [], []
    for k in range(n):
        if k in skip:
            continue
        t = t0 + k * PERIOD
        xy.append(frame(t, k))
        if k not in drop_heading:
            hd.append(frame(t + 0.0005, k))
    return xy, hd


class Pairing(unittest.TestCase):
    def test_all_paired(self):
        xy, hd = bus(50)
        pairs, unpaired, worst, cut = pair_pose_frames(xy, hd, WINDOW)
        self.assertEqual((len(pairs), unpaired, cut), (50, 0, None))
        self.assertAlmostEqual(worst, 0.0005)

    def test_missing_heading_without_outage_counts(self):
        xy, hd = bus(50, drop_heading={20})
        _, unpaired, _, cut = pair_pose_frames(xy, hd, WINDOW)
        self.assertEqual((unpaired, cut), (1, None))

    def test_pair_cut_by_the_link_going_down_is_allowed_once(self):
        # The link goes down between period 20's two sends and comes back at period 40.
        xy, hd = bus(60, drop_heading={20}, skip=set(range(21, 40)))
        outage = (20 * PERIOD + 0.0002, 40 * PERIOD - 0.001)
        pairs, unpaired, _, cut = pair_pose_frames(xy, hd, WINDOW, outage, outage[0] + 0.001)
        self.assertEqual((len(pairs), unpaired), (40, 0))
        self.assertIs(cut, xy[20])

    def test_only_the_last_pair_before_the_outage_may_be_cut(self):
        xy, hd = bus(60, drop_heading={19, 20}, skip=set(range(21, 40)))
        outage = (20 * PERIOD + 0.0002, 40 * PERIOD - 0.001)
        _, unpaired, _, cut = pair_pose_frames(xy, hd, WINDOW, outage, outage[0] + 0.001)
        self.assertEqual(unpaired, 1)
        self.assertIs(cut, xy[19 + 1])

    def test_missing_heading_after_the_outage_counts(self):
        xy, hd = bus(60, drop_heading={45}, skip=set(range(21, 40)))
        outage = (20 * PERIOD + 0.0002, 40 * PERIOD - 0.001)
        _, unpaired, _, cut = pair_pose_frames(xy, hd, WINDOW, outage, outage[0] + 0.001)
        self.assertEqual((unpaired, cut), (1, None))

    def test_missing_heading_long_before_the_outage_counts(self):
        # The last XY before the outage, but sent more than a pair window before the link went
        # down: that is a lost frame, not a cut pair.
        xy, hd = bus(60, drop_heading={20}, skip=set(range(21, 40)))
        outage = (20 * PERIOD + 0.5, 40 * PERIOD - 0.001)
        _, unpaired, _, cut = pair_pose_frames(xy, hd, WINDOW, outage, outage[0] + 0.001)
        self.assertEqual((unpaired, cut), (1, None))


class OwnRecord(unittest.TestCase):
    """match_own: each bus pose equals the next row(s) of the localizer's poses.csv."""

    DBC = hil_dbc.Dbc(os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                   "..", "..", "can", "agvloc.dbc"))

    def rows(self, n):
        # A vehicle moving 1 mm per tick along x, turning slowly.
        return [{"t_ns": k * 10_000_000, "x": 100.0 + k, "y": 20.0, "th": 0.001 * k, "valid": True}
                for k in range(n)]

    def pair(self, r, t):
        mxy, mhd = self.DBC.by_name("AGV_PoseXY"), self.DBC.by_name("AGV_PoseHeading")
        a, b = bytearray(8), bytearray(8)
        for d, m in ((a, mxy), (b, mhd)):
            m.signals["PoseValid"].encode(d, 1.0)
        mxy.signals["X"].encode(a, r["x"])
        mxy.signals["Y"].encode(a, r["y"])
        mhd.signals["Theta"].encode(b, r["th"])
        return (Frame(t=t, can_id=0x300, ext=False, data=bytes(a)),
                Frame(t=t + 0.0005, can_id=0x301, ext=False, data=bytes(b)))

    def run_match(self, own, sent):
        rep = Report(os.devnull)
        s = type("Setup", (), {"dbc": self.DBC})()
        pairs = [self.pair(own[k], 0.02 * k) for k in sent]
        out = match_own(s, rep, pairs, "poses.csv", own, 0.05 + 1e-4, 0.00005 + 1e-6)
        return rep, out

    def test_an_outage_of_any_length_skips_rows(self):
        # 450 ticks not sent (the link down): more than the old 200-row look-ahead.
        own = self.rows(700)
        sent = list(range(0, 100)) + list(range(550, 700))
        rep, out = self.run_match(own, sent)
        self.assertEqual(rep.failed, [])
        self.assertEqual(len(out), len(sent))

    def test_a_pose_the_localizer_never_wrote_fails(self):
        own = self.rows(300)
        rep = Report(os.devnull)
        s = type("Setup", (), {"dbc": self.DBC})()
        pairs = [self.pair(own[k], 0.02 * k) for k in range(300)]
        pairs[150] = self.pair({"x": 5000.0, "y": 20.0, "th": 0.0}, 3.0)
        match_own(s, rep, pairs, "poses.csv", own, 0.05 + 1e-4, 0.00005 + 1e-6)
        self.assertEqual(len(rep.failed), 1)


class PendingWindows(unittest.TestCase):
    """pending_windows: [exposure, fusion tick) of each fix, read from time_since_fix_ms."""

    def test_windows_from_the_record(self):
        rows, tsf = [], -1.0
        for k in range(100):
            t = 10_000_000_000 + k * 10_000_000
            if k == 30:
                tsf = 250.0  # fused at 10.30 s a fix exposed at 10.05 s (the first)
            elif k == 60:
                tsf = 40.0  # fused at 10.60 s a fix exposed at 10.56 s
            elif tsf >= 0:
                tsf += 10.0
            rows.append({"t_ns": t, "tsf_ms": tsf})
        self.assertEqual(pending_windows(rows), [(10_050_000_000, 10_300_000_000),
                                                 (10_560_000_000, 10_600_000_000)])

    def test_without_the_column(self):
        self.assertEqual(pending_windows([{"t_ns": 1, "tsf_ms": None}]), [])


class ReceivedOdometry(unittest.TestCase):
    """check_received_odometry: the decoded odometry is the sent odometry."""

    SENT = [(10_000_000_000 + k * 10_000_000, 0.001 * k, 0.0) for k in range(50)]

    def check(self, rx, scenario="nominal"):
        rep = Report(os.devnull)
        s = type("Setup", (), {"odom": self.SENT, "scenario": scenario})()
        check_received_odometry(s, {"odom_received": rx}, rep)
        return rep.failed

    def test_all_received_late(self):
        self.assertEqual(self.check([(t + 3_000_000, v, w) for t, v, w in self.SENT]), [])

    def test_a_value_never_sent_fails(self):
        rx = list(self.SENT)
        rx[20] = (rx[20][0], 7.5, 0.0)  # garbage that passed the decoder
        self.assertEqual(len(self.check(rx)), 1)

    def test_a_lost_sample_fails_unless_the_link_was_down(self):
        rx = self.SENT[:20] + self.SENT[30:]
        self.assertEqual(len(self.check(rx)), 1)
        self.assertEqual(self.check(rx, "link_flap"), [])

    def test_the_receive_lag_is_kept_for_the_reference_comparison(self):
        # analyse() checks the received-odometry reference only while the guest kept up.
        sc = {"odom_received": [(t + 3_900_000_000, v, w) for t, v, w in self.SENT]}
        s = type("Setup", (), {"odom": self.SENT, "scenario": "nominal"})()
        check_received_odometry(s, sc, Report(os.devnull))
        self.assertAlmostEqual(sc["rx_lag_median_ms"], 3900.0)


class HilConfig(unittest.TestCase):
    """The generated HIL configuration accepts fixes as late as the emulator delivers them."""

    def generate(self, text):
        import tempfile
        with tempfile.TemporaryDirectory() as d:
            src = os.path.join(d, "src.yaml")
            with open(src, "w") as f:
                f.write(text)
            args = type("Args", (), {"config": src, "iface": "vcan0", "set": None})()
            _, vals = prepare_config(args, d)
            return vals

    BASE = "camera:\n  driver: libcamera\ncan:\n  interface: can0\n"

    def test_without_a_fusion_section(self):
        vals = self.generate(self.BASE)
        self.assertEqual(vals[("fusion", "max_fix_delay_ms")], "10000")
        self.assertEqual(vals[("fusion", "history_capacity")], "2048")
        self.assertEqual(vals[("camera", "driver")], "replay")

    def test_with_a_fusion_section(self):
        vals = self.generate(self.BASE +
                             "fusion:\n  max_fix_delay_ms: 500\n  history_capacity: 256\n")
        self.assertEqual(vals[("fusion", "max_fix_delay_ms")], "10000")
        self.assertEqual(vals[("fusion", "history_capacity")], "2048")


class QuantizedRecording(unittest.TestCase):
    """The offline reference replays what the localizer on the bus has: the bus's odometry and
    no gyro (the HIL sends none; the localizer on the bus ignores imu.csv)."""

    def test_the_gyro_is_left_out_and_the_frames_kept(self):
        import tempfile
        with tempfile.TemporaryDirectory() as d:
            rec = os.path.join(d, "rec")
            os.makedirs(os.path.join(rec, "frames"))
            for name, text in (("odom.csv", "t_ns,v_mps,omega_radps\n0,0.5,0.01\n"),
                               ("imu.csv", "t_ns,gyro_z_radps\n0,0.01\n"),
                               ("frames.csv", "t_ns,file\n"), ("meta.yaml", "format_version: 1\n")):
                with open(os.path.join(rec, name), "w") as f:
                    f.write(text)
            dbc = hil_dbc.Dbc(os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                "..", "..", "can", "agvloc.dbc"))
            s = Setup(scenario="nominal", results=d, agvloc="", recording=rec, config="",
                      speed=1.0, dbc=dbc, odom=[(0, 0.5, 0.01)])
            out = quantize_recording(s, os.path.join(d, "q"))
            self.assertEqual(sorted(os.listdir(out)), ["frames", "frames.csv", "meta.yaml",
                                                       "odom.csv"])


if __name__ == "__main__":
    unittest.main()
