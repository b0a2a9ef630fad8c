"""A small, independent DBC reader and E2E checker for the HIL host checks.

Deliberately shares no code with the localizer's codec (algo/src/protocol): it reads the
contract (can/agvloc.dbc) as text and implements the CRC from the DBC's own description, so a
wrong table, a wrong DBC or a wrong encoder shows up as a mismatch. Python 3 stdlib only.

Supported: BO_/SG_ (Intel "@1" and Motorola "@0" byte order, signed/unsigned, scale/offset,
min/max), BA_ "GenMsgCycleTime"/"E2EDataID" on messages, VAL_ tables, 29-bit IDs (bit 31 set in
the DBC). Not supported (not used by the contract): multiplexed signals, float signals.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

EFF_FLAG = 0x80000000  # DBC marks 29-bit IDs with bit 31


@dataclass
class Signal:
    name: str
    start_bit: int
    length: int
    little_endian: bool
    signed: bool
    scale: float
    offset: float
    minimum: float
    maximum: float
    unit: str

    def raw_limits(self) -> tuple[int, int]:
        lo = -(1 << (self.length - 1)) if self.signed else 0
        hi = (1 << (self.length - 1)) - 1 if self.signed else (1 << self.length) - 1
        return lo, hi

    def _bit_positions(self) -> list[int]:
        """Payload bit indices (byte*8 + bit-in-byte), least significant signal bit first."""
        if self.little_endian:
            return [self.start_bit + i for i in range(self.length)]
        # Motorola: start_bit is the MSB in "sawtooth" numbering; walk towards the LSB.
        pos, bits = self.start_bit, []
        for _ in range(self.length):
            bits.append(pos)
            pos = pos - 1 if pos % 8 != 0 else pos + 15
        return list(reversed(bits))

    def get_raw(self, data: bytes) -> int:
        raw = 0
        for i, p in enumerate(self._bit_positions()):
            if p // 8 >= len(data):
                raise ValueError(f"signal {self.name} beyond a {len(data)}-byte payload")
            raw |= ((data[p // 8] >> (p % 8)) & 1) << i
        if self.signed and raw & (1 << (self.length - 1)):
            raw -= 1 << self.length
        return raw

    def put_raw(self, data: bytearray, raw: int) -> None:
        raw &= (1 << self.length) - 1
        for i, p in enumerate(self._bit_positions()):
            bit = (raw >> i) & 1
            data[p // 8] = (data[p // 8] & ~(1 << (p % 8))) | (bit << (p % 8))

    def decode(self, data: bytes) -> float:
        return self.get_raw(data) * self.scale + self.offset

    def encode(self, data: bytearray, phys: float) -> None:
        """Saturates to [min, max] like the contract says; never wraps."""
        phys = min(max(phys, self.minimum), self.maximum)
        raw = round((phys - self.offset) / self.scale)
        lo, hi = self.raw_limits()
        self.put_raw(data, min(max(raw, lo), hi))

    @property
    def resolution(self) -> float:
        return self.scale


@dataclass
class Message:
    frame_id: int  # without the EFF flag
    extended: bool
    name: str
    dlc: int
    sender: str
    signals: dict[str, Signal] = field(default_factory=dict)
    cycle_ms: int = 0
    data_id: int | None = None
    values: dict[str, dict[int, str]] = field(default_factory=dict)

    def decode(self, data: bytes) -> dict[str, float]:
        return {n: s.decode(data) for n, s in self.signals.items()}


_BO = re.compile(r"^BO_\s+(\d+)\s+(\w+)\s*:\s*(\d+)\s+(\w+)")
_SG = re.compile(r"^\s*SG_\s+(\w+)\s*(\S*)\s*:\s*(\d+)\|(\d+)@([01])([+-])\s*"
                 r"\(\s*([-+0-9.eE]+)\s*,\s*([-+0-9.eE]+)\s*\)\s*"
                 r"\[\s*([-+0-9.eE]+)\s*\|\s*([-+0-9.eE]+)\s*\]\s*\"([^\"]*)\"")
_BA_MSG = re.compile(r'^BA_\s+"(\w+)"\s+BO_\s+(\d+)\s+(-?\d+)\s*;')
_VAL = re.compile(r"^VAL_\s+(\d+)\s+(\w+)\s+(.*);")


class Dbc:
    def __init__(self, path: str):
        self.path = path
        self.messages: dict[str, Message] = {}
        self._by_id: dict[tuple[int, bool], Message] = {}
        current: Message | None = None
        with open(path, encoding="utf-8") as f:
            for lineno, line in enumerate(f, 1):
                m = _BO.match(line)
                if m:
                    raw_id = int(m.group(1))
                    ext = bool(raw_id & EFF_FLAG)
                    current = Message(raw_id & ~EFF_FLAG, ext, m.group(2), int(m.group(3)),
                                      m.group(4))
                    self.messages[current.name] = current
                    self._by_id[(current.frame_id, ext)] = current
                    continue
                m = _SG.match(line)
                if m:
                    if current is None:
                        raise ValueError(f"{path}:{lineno}: SG_ outside a BO_")
                    if m.group(2):
                        raise ValueError(f"{path}:{lineno}: multiplexed signals not supported")
                    s = Signal(m.group(1), int(m.group(3)), int(m.group(4)), m.group(5) == "1",
                               m.group(6) == "-", float(m.group(7)), float(m.group(8)),
                               float(m.group(9)), float(m.group(10)), m.group(11))
                    current.signals[s.name] = s
                    continue
                if not line.startswith(" "):
                    current = None
                m = _BA_MSG.match(line)
                if m:
                    msg = self._find_raw_id(int(m.group(2)), path, lineno)
                    if m.group(1) == "GenMsgCycleTime":
                        msg.cycle_ms = int(m.group(3))
                    elif m.group(1) == "E2EDataID":
                        msg.data_id = int(m.group(3))
                    continue
                m = _VAL.match(line)
                if m:
                    msg = self._find_raw_id(int(m.group(1)), path, lineno)
                    pairs = re.findall(r'(-?\d+)\s+"([^"]*)"', m.group(3))
                    msg.values[m.group(2)] = {int(k): v for k, v in pairs}
        if not self.messages:
            raise ValueError(f"{path}: no BO_ messages")

    def _find_raw_id(self, raw_id: int, path: str, lineno: int) -> Message:
        key = (raw_id & ~EFF_FLAG, bool(raw_id & EFF_FLAG))
        if key not in self._by_id:
            raise ValueError(f"{path}:{lineno}: attribute for unknown message {raw_id}")
        return self._by_id[key]

    def by_name(self, name: str) -> Message:
        if name not in self.messages:
            raise KeyError(f"{self.path} has no message {name}")
        return self.messages[name]

    def with_ids(self, base_id: int, extended: bool, odom_id: int | None = None,
                 odom_extended: bool = False, odom_name: str = "") -> dict[tuple[int, bool], Message]:
        """ID map for a deployment whose base ID differs from the DBC's: output messages keep
        their offset from the DBC's first AGVLOC message; the odometry message gets odom_id."""
        tx = sorted((m for m in self.messages.values() if m.sender != "MC"),
                    key=lambda m: m.frame_id)
        dbc_base = tx[0].frame_id
        out = {}
        for m in tx:
            out[(base_id + m.frame_id - dbc_base, extended)] = m
        if odom_name and odom_id is not None:
            out[(odom_id, odom_extended)] = self.by_name(odom_name)
        return out


def crc8_sae_j1850(data: bytes) -> int:
    """CRC-8 SAE J1850: poly 0x1D, init 0xFF, xor-out 0xFF, not reflected (bitwise, no table)."""
    crc = 0xFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def e2e_crc(data_id: int, data: bytes) -> int:
    """As the DBC comment says: over the data ID (low byte, high byte), then bytes 1..7."""
    return crc8_sae_j1850(bytes([data_id & 0xFF, (data_id >> 8) & 0xFF]) + bytes(data[1:8]))


def e2e_protect(data_id: int, counter: int, data: bytearray) -> None:
    data[1] = (data[1] & 0xF0) | (counter & 0x0F)
    data[0] = e2e_crc(data_id, data)


def e2e_ok(data_id: int, data: bytes) -> bool:
    return len(data) == 8 and data[0] == e2e_crc(data_id, data) and (data[1] & 0x0F) != 15


def alive_counter(data: bytes) -> int:
    return data[1] & 0x0F
