#include "agv/protocol/dbc.hpp"

#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace agv::protocol {

std::string format_number(double v) {
  char buf[400];  // fixed notation of any double fits
  for (int prec = 1; prec <= 17; ++prec) {
    std::snprintf(buf, sizeof buf, "%.*g", prec, v);
    if (std::strtod(buf, nullptr) == v) break;
  }
  // Not every DBC reader takes an exponent (npm candied silently drops a signal whose factor is
  // "1e-05"): the shortest fixed notation that reads back the same instead.
  if (std::strchr(buf, 'e') != nullptr) {
    for (int decimals = 0; decimals <= 340; ++decimals) {
      std::snprintf(buf, sizeof buf, "%.*f", decimals, v);
      if (std::strtod(buf, nullptr) == v) break;
    }
  }
  return buf;
}

namespace {

std::uint32_t dbc_id(const ProtocolConfig& cfg, Msg m) {
  return can_id_of(cfg, m) | (is_extended(cfg, m) ? 0x80000000u : 0u);
}

const char* kGeneralComment =
    "agvloc CAN protocol. All multi-byte signals Intel (little-endian). Byte 0 of every frame "
    "is CRC-8 SAE J1850 (poly 0x1D, init 0xFF, xor-out 0xFF) computed over the 16-bit data ID "
    "(attribute E2EDataID; low byte first, then high byte) followed by frame bytes 1..7. Bits "
    "0..3 of byte 1 are the alive counter 0..14 (+1 per frame of the same ID, 14 wraps to 0, 15 "
    "invalid). Receivers reject frames with wrong length, bad CRC, or repeated or jumping "
    "counter. Output frames use CAN ID base_id + offset (default base 0x300, 11-bit; 29-bit "
    "optional). Signals saturate at their min/max, they never wrap. Docs: docs/guide/can.md.";

}  // namespace

std::string render_dbc(const ProtocolConfig& cfg) {
  std::string s;
  s += "VERSION \"agvloc protocol " + std::to_string(kProtocolVersion) + "\"\n\n";
  s += "NS_ :\n\tCM_\n\tBA_DEF_\n\tBA_\n\tVAL_\n\tBA_DEF_DEF_\n\n";
  s += "BS_:\n\nBU_: AGVLOC MC\n\n";
  for (const MessageDef& m : message_table()) {
    const char* tx = m.dir == Direction::kTx ? "AGVLOC" : "MC";
    const char* rx = m.dir == Direction::kTx ? "MC" : "AGVLOC";
    s += "BO_ " + std::to_string(dbc_id(cfg, m.msg)) + " " + m.name + ": " + std::to_string(m.dlc) +
         " " + tx + "\n";
    for (const SignalDef& g : m.signals) {
      s += std::string(" SG_ ") + g.name + " : " + std::to_string(g.start_bit) + "|" +
           std::to_string(g.length) + (g.little_endian ? "@1" : "@0") + (g.is_signed ? "-" : "+") +
           " (" + format_number(g.scale) + "," + format_number(g.offset) + ") [" +
           format_number(g.min) + "|" + format_number(g.max) + "] \"" + g.unit + "\" " + rx + "\n";
    }
    s += "\n";
  }
  s += "CM_ \"" + std::string(kGeneralComment) + "\";\n";
  for (const MessageDef& m : message_table()) {
    s += "CM_ BO_ " + std::to_string(dbc_id(cfg, m.msg)) + " \"" + m.comment + "\";\n";
    for (const SignalDef& g : m.signals) {
      s += "CM_ SG_ " + std::to_string(dbc_id(cfg, m.msg)) + " " + g.name + " \"" + g.comment +
           "\";\n";
    }
  }
  s += "BA_DEF_ BO_ \"GenMsgCycleTime\" INT 0 65535;\n";
  s += "BA_DEF_ BO_ \"E2EDataID\" INT 0 65535;\n";
  s += "BA_DEF_ \"ProtocolVersion\" INT 0 15;\n";
  s += "BA_DEF_DEF_ \"GenMsgCycleTime\" 0;\n";
  s += "BA_DEF_DEF_ \"E2EDataID\" 0;\n";
  s += "BA_DEF_DEF_ \"ProtocolVersion\" 0;\n";
  s += "BA_ \"ProtocolVersion\" " + std::to_string(kProtocolVersion) + ";\n";
  for (const MessageDef& m : message_table()) {
    s += "BA_ \"GenMsgCycleTime\" BO_ " + std::to_string(dbc_id(cfg, m.msg)) + " " +
         std::to_string(cycle_ms_of(cfg, m.msg)) + ";\n";
    s += "BA_ \"E2EDataID\" BO_ " + std::to_string(dbc_id(cfg, m.msg)) + " " +
         std::to_string(m.data_id) + ";\n";
  }
  s += "VAL_ " + std::to_string(dbc_id(cfg, Msg::kStatus)) +
       " Health 0 \"OK\" 1 \"DEGRADED\" 2 \"LOST\" 3 \"FAULT\" ;\n";
  return s;
}

std::string render_markdown_table(const ProtocolConfig& cfg) {
  std::string s;
  s += "| Message | CAN ID | Dir | Cycle | E2E data ID | Signal | Bits (start\\|len) | Type | "
       "Scale | Offset | Min | Max | Unit |\n";
  s += "|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  char buf[32];
  for (const MessageDef& m : message_table()) {
    std::snprintf(buf, sizeof buf, "0x%03X", can_id_of(cfg, m.msg));
    std::string head = std::string("| ") + m.name + " | " + buf + " | " +
                       (m.dir == Direction::kTx ? "out" : "in") + " | " +
                       std::to_string(cycle_ms_of(cfg, m.msg)) + " ms | ";
    std::snprintf(buf, sizeof buf, "0x%04X", m.data_id);
    head += std::string(buf) + " | ";
    bool first = true;
    for (const SignalDef& g : m.signals) {
      s += first ? head : std::string("| | | | | | ");
      first = false;
      s += std::string(g.name) + " | " + std::to_string(g.start_bit) + "\\|" +
           std::to_string(g.length) + " | " + (g.is_signed ? "signed" : "unsigned") + " | " +
           format_number(g.scale) + " | " + format_number(g.offset) + " | " + format_number(g.min) +
           " | " + format_number(g.max) + " | " + g.unit + " |\n";
    }
  }
  return s;
}

}  // namespace agv::protocol
