#include "agv/protocol/e2e.hpp"

namespace agv::protocol {

namespace {
// Register update without init/xor-out so that e2e_crc can chain data ID and payload.
std::uint8_t crc8_update(std::uint8_t crc, const std::uint8_t* data, std::size_t len) {
  for (std::size_t i = 0; i < len; ++i) {
    crc = static_cast<std::uint8_t>(crc ^ data[i]);
    for (int b = 0; b < 8; ++b) {
      crc = (crc & 0x80u) ? static_cast<std::uint8_t>((crc << 1) ^ 0x1Du)
                          : static_cast<std::uint8_t>(crc << 1);
    }
  }
  return crc;
}
}  // namespace

std::uint8_t crc8_sae_j1850(const std::uint8_t* data, std::size_t len) {
  return static_cast<std::uint8_t>(crc8_update(0xFFu, data, len) ^ 0xFFu);
}

std::uint8_t e2e_crc(std::uint16_t data_id, const std::uint8_t data[8]) {
  std::uint8_t buf[9];
  buf[0] = static_cast<std::uint8_t>(data_id & 0xFFu);
  buf[1] = static_cast<std::uint8_t>(data_id >> 8);
  for (int i = 1; i < 8; ++i) buf[i + 1] = data[i];
  return crc8_sae_j1850(buf, sizeof buf);
}

void e2e_protect(std::uint16_t data_id, std::uint8_t counter, std::uint8_t data[8]) {
  data[1] = static_cast<std::uint8_t>((data[1] & 0xF0u) | (counter % kE2eCounterModulo));
  data[0] = e2e_crc(data_id, data);
}

const char* to_string(E2eStatus s) {
  switch (s) {
    case E2eStatus::kOk:
      return "ok";
    case E2eStatus::kOkSomeLost:
      return "ok-some-lost";
    case E2eStatus::kInitial:
      return "initial";
    case E2eStatus::kRepeated:
      return "repeated";
    case E2eStatus::kWrongSequence:
      return "wrong-sequence";
    case E2eStatus::kBadCrc:
      return "bad-crc";
    case E2eStatus::kBadLength:
      return "bad-length";
    case E2eStatus::kBadCounter:
      return "bad-counter";
  }
  return "?";
}

E2eStatus E2eChecker::check(const hal::CanFrame& frame) {
  if (frame.len != kE2eFrameLen) {
    ++counters_.bad_length;
    return E2eStatus::kBadLength;
  }
  if (e2e_crc(cfg_.data_id, frame.data) != frame.data[0]) {
    ++counters_.bad_crc;
    return E2eStatus::kBadCrc;
  }
  const std::uint8_t counter = frame.data[1] & 0x0Fu;
  if (counter >= kE2eCounterModulo) {
    ++counters_.bad_counter;
    return E2eStatus::kBadCounter;
  }
  if (!have_ref_) {
    have_ref_ = true;
    last_counter_ = counter;
    ++counters_.ok;
    return E2eStatus::kInitial;
  }
  const int delta = (counter - last_counter_ + kE2eCounterModulo) % kE2eCounterModulo;
  if (delta == 0) {
    ++counters_.repeated;
    return E2eStatus::kRepeated;
  }
  last_counter_ = counter;  // a jump also resynchronises (see header)
  const int max_delta = cfg_.max_delta_counter < 1 ? 1 : cfg_.max_delta_counter;
  if (delta > max_delta) {
    ++counters_.wrong_sequence;
    return E2eStatus::kWrongSequence;
  }
  if (delta == 1) {
    ++counters_.ok;
    return E2eStatus::kOk;
  }
  ++counters_.ok_some_lost;
  counters_.lost_frames += static_cast<std::uint64_t>(delta - 1);
  return E2eStatus::kOkSomeLost;
}

}  // namespace agv::protocol
