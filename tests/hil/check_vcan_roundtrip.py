#!/usr/bin/python3
"""Host side of the vcan round trip: parses the guest's candump log with python-can (an
implementation independent of can-utils) and checks every frame cansend put on the bus came back
exactly once, bit for bit.  Usage: check_vcan_roundtrip.py CAPTURE.log"""
import sys

import can

# (arbitration_id, is_extended, is_remote, is_fd, data) -- same order as guest/vcan_roundtrip.sh
EXPECTED = [
    (0x123, False, False, False, bytes.fromhex("DEADBEEF")),
    (0x1ABCDEF0, True, False, False, bytes.fromhex("0011223344556677")),
    (0x7FF, False, False, False, b""),
    (0x100, False, True, False, b""),
    (0x000, False, False, False, bytes.fromhex("01")),
    (0x456, False, False, True, bytes(range(20))),
]


def main() -> int:
    path = sys.argv[1]
    got = []
    for msg in can.CanutilsLogReader(path):
        if msg.is_error_frame:
            continue
        got.append((msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame, msg.is_fd,
                    bytes(msg.data), msg.channel, msg.timestamp))
    errors = []
    if len(got) != len(EXPECTED):
        errors.append(f"expected {len(EXPECTED)} frames, captured {len(got)}")
    for i, (exp, g) in enumerate(zip(EXPECTED, got)):
        if exp != g[:5]:
            errors.append(f"frame {i}: expected {exp}, got {g[:5]}")
        if g[5] != "vcan0":
            errors.append(f"frame {i}: captured on {g[5]!r}, expected 'vcan0'")
    stamps = [g[6] for g in got]
    if any(b < a for a, b in zip(stamps, stamps[1:])):
        errors.append(f"timestamps not monotonic: {stamps}")
    if errors:
        print(f"FAIL: vcan round trip ({path}):")
        for e in errors:
            print("  " + e)
        return 1
    print(f"PASS: {len(got)} frames round-tripped through the guest kernel's vcan0")
    return 0


if __name__ == "__main__":
    sys.exit(main())
