// CAN frames into the odometry decoder and the E2E check (docs/guide/can.md). The first byte picks
// the configuration (mode, E2E on/off, 11/29-bit ID, max_delta_counter), then every 12 bytes are
// one frame: flags, a signed time step, two speed words and 8 data bytes. Flag bit 0 makes it a
// correctly protected odometry frame (encode_odometry with the given counter) so the fuzzer gets
// past the CRC; other bits pick the ID, the length and mutations of the encoded bytes.
// Properties: the counters add up (accepted + rejections = odometry frames seen; E2E ok + lost +
// rejected = checks), lost frames match the reported gaps, accepted samples are finite and in
// time order, and the decoder's E2E view agrees with a separate E2eChecker on the same frames.
#include <cmath>
#include <cstring>

#include "agv/protocol/codec.hpp"
#include "agv/protocol/e2e.hpp"
#include "fuzz_check.hpp"

namespace p = agv::protocol;

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  if (size < 1) return 0;
  p::ProtocolConfig cfg;
  const unsigned char c = data[0];
  cfg.odometry.mode = (c & 1) ? p::OdometryMode::kTwist : p::OdometryMode::kWheels;
  cfg.odometry.protected_e2e = (c & 2) == 0;
  cfg.extended_ids = (c & 4) != 0;
  cfg.odometry.extended_id = cfg.extended_ids;
  cfg.odometry.max_delta_counter = static_cast<std::uint8_t>(1 + (c >> 4) % 14);
  FUZZ_CHECK(p::validate(cfg).empty(), "config");
  p::OdometryDecoder dec(cfg);
  // The same E2E check on its own, with the data ID encode_odometry protects with (found once
  // per mode by trying all 2^16).
  static int data_ids[2] = {-1, -1};
  int& data_id = data_ids[c & 1];
  if (data_id < 0) {
    agv::hal::CanFrame probe;
    p::encode_odometry(cfg, 0.0, 0.0, 0, &probe);
    for (int id = 0; id <= 0xFFFF && data_id < 0; ++id) {
      if (p::e2e_crc(static_cast<std::uint16_t>(id), probe.data) == probe.data[0]) data_id = id;
    }
    FUZZ_CHECK(data_id >= 0, "no data ID");
  }
  p::E2eChecker checker({static_cast<std::uint16_t>(data_id), cfg.odometry.max_delta_counter});

  std::uint64_t seen = 0, ok = 0, not_odom = 0, lost_reported = 0, e2e_checks = 0,
                e2e_some_lost = 0;
  std::int64_t t = 1'000'000'000, last_ok_t = INT64_MIN;
  for (std::size_t at = 1; at + 12 <= size; at += 12) {
    const unsigned char* b = data + at;
    const unsigned char flags = b[0];
    t += static_cast<std::int64_t>(static_cast<signed char>(b[1])) * 1'000'000;
    agv::hal::CanFrame f;
    if (flags & 1) {
      const double a = static_cast<std::int16_t>(b[2] | b[3] << 8) * 1e-3;
      const double v = static_cast<std::int16_t>(b[4] | b[5] << 8) * 1e-3;
      p::encode_odometry(cfg, a, v, static_cast<std::uint8_t>(b[6] % 15), &f);
      if (flags & 2) f.data[b[7] & 7] ^= b[8];  // corrupt one byte
      if (flags & 4) f.data[1] = static_cast<std::uint8_t>((f.data[1] & 0xF0) | 0x0F);
    } else {
      f.id = dec.can_id();
      f.extended = dec.extended();
      f.len = 8;
      std::memcpy(f.data, b + 4, 8);
    }
    if (flags & 8) f.len = static_cast<std::uint8_t>(b[9] % 9);
    if (flags & 16) f.id = (f.id + 1 + b[10]) & (f.extended ? p::kCanExtIdMask : p::kCanStdIdMask);
    if (flags & 32) f.extended = !f.extended;
    f.t_ns = t;

    const bool is_odom = f.id == dec.can_id() && f.extended == dec.extended();
    if (is_odom && cfg.odometry.protected_e2e && f.len == 8 &&
        !(last_ok_t != INT64_MIN && f.t_ns < last_ok_t)) {
      // The decoder checks E2E only on frames that are not stale: mirror that.
      const p::E2eStatus st = checker.check(f);
      ++e2e_checks;
      if (st == p::E2eStatus::kOkSomeLost) ++e2e_some_lost;
    }
    p::OdomSample s;
    s.v_mps = 12345.0;
    const p::DecodeResult r = dec.decode(f, &s);
    FUZZ_CHECK(p::to_string(r) != nullptr, "result name");
    if (r == p::DecodeResult::kNotOdometry) {
      FUZZ_CHECK(!is_odom, "odometry frame ignored");
      ++not_odom;
      continue;
    }
    FUZZ_CHECK(is_odom, "other frame decoded");
    ++seen;
    if (r != p::DecodeResult::kOk) {
      FUZZ_CHECK(s.v_mps == 12345.0, "sample written on rejection");
      continue;
    }
    ++ok;
    FUZZ_CHECK(std::isfinite(s.v_mps) && std::isfinite(s.omega_radps) &&
                   std::isfinite(s.left_mps) && std::isfinite(s.right_mps),
               "non-finite sample");
    FUZZ_CHECK(s.t_ns == f.t_ns && (last_ok_t == INT64_MIN || s.t_ns >= last_ok_t), "time order");
    FUZZ_CHECK(s.lost_before < cfg.odometry.max_delta_counter, "lost %u", s.lost_before);
    lost_reported += s.lost_before;
    last_ok_t = s.t_ns;
    FUZZ_CHECK(dec.last_accepted_ns() == f.t_ns, "last accepted");
  }
  const p::OdometryCounters& k = dec.counters();
  FUZZ_CHECK(k.accepted == ok, "accepted %llu vs %llu", static_cast<unsigned long long>(k.accepted),
             static_cast<unsigned long long>(ok));
  FUZZ_CHECK(k.accepted + k.rejected() == seen, "accepted + rejected != frames seen");
  FUZZ_CHECK(k.lost_frames == lost_reported, "lost frames");
  if (!cfg.odometry.protected_e2e) {
    FUZZ_CHECK(k.bad_crc + k.repeated + k.counter_jump + k.bad_counter + k.lost_frames == 0,
               "E2E counted while unprotected");
    return 0;
  }
  const p::E2eCounters& e = checker.counters();
  FUZZ_CHECK(e.ok + e.ok_some_lost + e.rejected() == e2e_checks, "E2E counters do not add up");
  FUZZ_CHECK(e.ok_some_lost == e2e_some_lost, "ok_some_lost");
  FUZZ_CHECK(e.lost_frames <= e.ok_some_lost * (cfg.odometry.max_delta_counter - 1u), "gaps");
  FUZZ_CHECK(e.lost_frames == k.lost_frames && e.ok + e.ok_some_lost == k.accepted &&
                 e.bad_crc == k.bad_crc && e.repeated == k.repeated &&
                 e.wrong_sequence == k.counter_jump && e.bad_counter == k.bad_counter,
             "decoder and E2E checker disagree");
  return 0;
}
