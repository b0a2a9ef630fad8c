// The DBC file is the contract: read it with a small independent parser and check every message
// and signal against the codec's table, so the two cannot drift apart.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <string>

#include "agv/protocol/codec.hpp"
#include "agv/protocol/dbc.hpp"
#include "agv/protocol/signals.hpp"

namespace p = agv::protocol;

namespace {

struct DbcSignal {
  int start = -1, length = -1;
  bool little_endian = false, is_signed = false;
  double scale = 0, offset = 0, min = 0, max = 0;
  std::string unit, receiver;
  bool has_comment = false;
};
struct DbcMessage {
  std::uint32_t id = 0;  // DBC ID (bit 31 = extended)
  std::string name, sender;
  int dlc = -1;
  std::map<std::string, DbcSignal> signals;
  long cycle_ms = -1, data_id = -1;
  bool has_comment = false;
};
struct Dbc {
  std::map<std::string, DbcMessage> by_name;
  std::map<std::uint32_t, std::string> name_of_id;
  std::string error;
};

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

Dbc parse_dbc(const std::string& text) {
  Dbc dbc;
  const std::regex bo(R"re(^BO_ (\d+) (\w+): (\d+) (\w+)\s*$)re");
  const std::regex sg(
      R"re(^ SG_ (\w+) : (\d+)\|(\d+)@([01])([+-]) \(([-+0-9.eE]+),([-+0-9.eE]+)\) \[([-+0-9.eE]+)\|([-+0-9.eE]+)\] "([^"]*)" (\w+)\s*$)re");
  const std::regex cm_bo(R"re(^CM_ BO_ (\d+) ".+";$)re");
  const std::regex cm_sg(R"re(^CM_ SG_ (\d+) (\w+) ".+";$)re");
  const std::regex ba(R"re(^BA_ "(\w+)" BO_ (\d+) (\d+);$)re");
  std::istringstream in(text);
  std::string line;
  DbcMessage* cur = nullptr;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    std::smatch m;
    if (std::regex_match(line, m, bo)) {
      DbcMessage msg;
      msg.id = static_cast<std::uint32_t>(std::stoul(m[1]));
      msg.name = m[2];
      msg.dlc = std::stoi(m[3]);
      msg.sender = m[4];
      dbc.name_of_id[msg.id] = msg.name;
      cur = &(dbc.by_name[msg.name] = msg);
    } else if (line.rfind(" SG_", 0) == 0) {
      if (!std::regex_match(line, m, sg) || !cur) {
        dbc.error = "line " + std::to_string(n) + ": unparsed signal: " + line;
        return dbc;
      }
      DbcSignal s;
      s.start = std::stoi(m[2]);
      s.length = std::stoi(m[3]);
      s.little_endian = m[4] == "1";
      s.is_signed = m[5] == "-";
      s.scale = std::stod(m[6]);
      s.offset = std::stod(m[7]);
      s.min = std::stod(m[8]);
      s.max = std::stod(m[9]);
      s.unit = m[10];
      s.receiver = m[11];
      cur->signals[m[1]] = s;
    } else if (std::regex_match(line, m, cm_bo)) {
      dbc.by_name[dbc.name_of_id[static_cast<std::uint32_t>(std::stoul(m[1]))]].has_comment = true;
    } else if (std::regex_match(line, m, cm_sg)) {
      DbcMessage& msg = dbc.by_name[dbc.name_of_id[static_cast<std::uint32_t>(std::stoul(m[1]))]];
      msg.signals[m[2]].has_comment = true;
    } else if (std::regex_match(line, m, ba)) {
      DbcMessage& msg = dbc.by_name[dbc.name_of_id[static_cast<std::uint32_t>(std::stoul(m[2]))]];
      if (m[1] == "GenMsgCycleTime") msg.cycle_ms = std::stol(m[3]);
      if (m[1] == "E2EDataID") msg.data_id = std::stol(m[3]);
    } else if (line.empty() || line[0] != ' ') {
      cur = nullptr;
    }
  }
  return dbc;
}

bool near_rel(double a, double b) {
  return std::fabs(a - b) <= 1e-12 * std::max(1.0, std::fabs(b));
}

const std::string kDbcPath = std::string(AGV_SOURCE_DIR) + "/can/agvloc.dbc";
const std::string kRegen =
    "; regenerate with: build/<dir>/tests/can/agv_can_tool dbc > can/agvloc.dbc";

}  // namespace

TEST(Dbc, EverySignalMatchesTheCodecTable) {
  const std::string text = read_text(kDbcPath);
  ASSERT_FALSE(text.empty()) << kDbcPath;
  const Dbc dbc = parse_dbc(text);
  ASSERT_EQ(dbc.error, "");
  const p::ProtocolConfig cfg;
  ASSERT_EQ(dbc.by_name.size(), p::message_table().size());
  for (const p::MessageDef& m : p::message_table()) {
    SCOPED_TRACE(m.name);
    auto it = dbc.by_name.find(m.name);
    ASSERT_NE(it, dbc.by_name.end());
    const DbcMessage& dm = it->second;
    EXPECT_EQ(dm.id, p::can_id_of(cfg, m.msg));
    EXPECT_EQ(dm.dlc, m.dlc);
    EXPECT_EQ(dm.sender, m.dir == p::Direction::kTx ? "AGVLOC" : "MC");
    EXPECT_EQ(dm.cycle_ms, static_cast<long>(m.cycle_ms));
    EXPECT_EQ(dm.data_id, static_cast<long>(m.data_id));
    EXPECT_TRUE(dm.has_comment);
    EXPECT_EQ(dm.signals.size(), m.signals.size());
    for (const p::SignalDef& s : m.signals) {
      SCOPED_TRACE(s.name);
      auto si = dm.signals.find(s.name);
      ASSERT_NE(si, dm.signals.end());
      const DbcSignal& d = si->second;
      EXPECT_EQ(d.start, s.start_bit);
      EXPECT_EQ(d.length, s.length);
      EXPECT_EQ(d.little_endian, s.little_endian);
      EXPECT_EQ(d.is_signed, s.is_signed);
      EXPECT_TRUE(near_rel(d.scale, s.scale)) << d.scale;
      EXPECT_TRUE(near_rel(d.offset, s.offset)) << d.offset;
      EXPECT_TRUE(near_rel(d.min, s.min)) << d.min;
      EXPECT_TRUE(near_rel(d.max, s.max)) << d.max;
      EXPECT_EQ(d.unit, s.unit);
      EXPECT_EQ(d.receiver, m.dir == p::Direction::kTx ? "MC" : "AGVLOC");
      EXPECT_TRUE(d.has_comment);
    }
  }
}

TEST(Dbc, ParserCatchesADriftedSignal) {
  // The check above must be able to fail: change one field and see the parser pick it up.
  std::string text = read_text(kDbcPath);
  const std::string from = " SG_ X : 16|24@1- (0.1,0)";
  const auto pos = text.find(from);
  ASSERT_NE(pos, std::string::npos);
  text.replace(pos, from.size(), " SG_ X : 16|24@1- (0.01,0)");
  const Dbc dbc = parse_dbc(text);
  ASSERT_EQ(dbc.error, "");
  EXPECT_FALSE(near_rel(dbc.by_name.at("AGV_PoseXY").signals.at("X").scale, 0.1));
}

TEST(Dbc, CommittedFileIsTheRenderedContract) {
  EXPECT_EQ(read_text(kDbcPath), p::render_dbc(p::ProtocolConfig{})) << kRegen;
}

TEST(Dbc, RenderHonoursBaseIdAndExtendedIds) {
  p::ProtocolConfig cfg;
  cfg.base_id = 0x18FF1000;
  cfg.extended_ids = true;
  cfg.odometry.extended_id = true;
  cfg.odometry.can_id = 0x18FF2000;
  const Dbc dbc = parse_dbc(p::render_dbc(cfg));
  ASSERT_EQ(dbc.error, "");
  EXPECT_EQ(dbc.by_name.at("AGV_PoseXY").id, 0x18FF1000u | 0x80000000u);
  EXPECT_EQ(dbc.by_name.at("MC_OdomWheels").id, 0x18FF2000u | 0x80000000u);
}

// The DBC states the rates the vehicle is configured to send at, not a fixed 100 Hz; the signal
// table's nominal periods are the configuration's defaults.
TEST(Dbc, CycleTimesFollowTheConfiguredRates) {
  const p::ProtocolConfig nominal;
  for (const p::MessageDef& m : p::message_table()) {
    EXPECT_EQ(p::cycle_ms_of(nominal, m.msg), m.cycle_ms) << m.name;
  }
  p::ProtocolConfig cfg;
  cfg.output_period_ms = 20.0;      // loop.output_rate_hz 50
  cfg.heartbeat_period_ms = 500.0;  // loop.heartbeat_rate_hz 2
  ASSERT_EQ(p::validate(cfg), "");
  const std::string dbc = p::render_dbc(cfg);
  const auto cycle_of = [&](p::Msg m) {
    const std::regex re("BA_ \"GenMsgCycleTime\" BO_ " + std::to_string(p::can_id_of(cfg, m)) +
                        " ([0-9]+);");
    std::smatch match;
    return std::regex_search(dbc, match, re) ? std::stoi(match[1]) : -1;
  };
  EXPECT_EQ(cycle_of(p::Msg::kPoseXY), 20);
  EXPECT_EQ(cycle_of(p::Msg::kStatus), 20);
  EXPECT_EQ(cycle_of(p::Msg::kHeartbeat), 500);
  EXPECT_EQ(cycle_of(p::Msg::kOdomWheels), 10);  // what the motor controller sends: nominal
  cfg.output_period_ms = 0.0;
  EXPECT_NE(p::validate(cfg), "");
}

TEST(Dbc, DocsFrameTableIsCurrent) {
  const std::string doc = read_text(std::string(AGV_SOURCE_DIR) + "/docs/guide/can.md");
  ASSERT_FALSE(doc.empty());
  EXPECT_NE(doc.find(p::render_markdown_table(p::ProtocolConfig{})), std::string::npos)
      << "docs/guide/can.md frame table is stale; regenerate with: agv_can_tool doc-table";
}

TEST(Dbc, FormatNumberIsShortestRoundTrip) {
  EXPECT_EQ(p::format_number(0.1), "0.1");
  EXPECT_EQ(p::format_number(-838860.8), "-838860.8");
  EXPECT_EQ(p::format_number(16777215), "16777215");
  EXPECT_EQ(p::format_number(0.0001), "0.0001");
  // No exponents: npm candied drops a signal whose factor reads "1e-05" (AGV_Gyro.GyroZ).
  EXPECT_EQ(p::format_number(0.00001), "0.00001");
  EXPECT_EQ(p::format_number(-2.5e-7), "-0.00000025");
  EXPECT_EQ(p::format_number(1e20), "100000000000000000000");
}
