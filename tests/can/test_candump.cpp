#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>

#include "agv/can/candump_file.hpp"
#include "agv/protocol/candump.hpp"
#include "agv/protocol/codec.hpp"

namespace p = agv::protocol;

namespace {
p::CandumpRecord parse_ok(const std::string& line) {
  p::CandumpRecord r;
  std::string err;
  EXPECT_TRUE(p::parse_candump_line(line, &r, &err)) << line << ": " << err;
  return r;
}
std::string parse_err(const std::string& line) {
  p::CandumpRecord r;
  std::string err;
  EXPECT_FALSE(p::parse_candump_line(line, &r, &err)) << line;
  return err;
}
std::string temp_path(const char* name) {
  return ::testing::TempDir() + "/agv_can_" + std::to_string(::getpid()) + "_" + name;
}
}  // namespace

TEST(CandumpLine, ParsesStandardExtendedRemoteAndError) {
  p::CandumpRecord r = parse_ok("(1436509052.249713) vcan0 044#2A366C2BBA\n");
  EXPECT_EQ(r.t_ns, 1436509052249713000);
  EXPECT_EQ(r.frame.t_ns, r.t_ns);
  EXPECT_EQ(r.iface, "vcan0");
  EXPECT_EQ(r.frame.id, 0x044u);
  EXPECT_FALSE(r.frame.extended);
  ASSERT_EQ(r.frame.len, 5);
  EXPECT_EQ(r.frame.data[0], 0x2A);
  EXPECT_EQ(r.frame.data[4], 0xBA);

  r = parse_ok("(0000000001.000001) can1 1ABCDEF0#");
  EXPECT_TRUE(r.frame.extended);
  EXPECT_EQ(r.frame.id, 0x1ABCDEF0u);
  EXPECT_EQ(r.frame.len, 0);
  EXPECT_EQ(r.t_ns, 1'000'001'000);

  r = parse_ok("(1.000000) can0 123#R");
  EXPECT_TRUE(r.rtr);
  r = parse_ok("(1.000000) can0 123#R3");
  EXPECT_TRUE(r.rtr);
  EXPECT_EQ(r.frame.len, 3);

  r = parse_ok("(1.000000) can0 20000040#0000000000000000");
  EXPECT_TRUE(r.error_frame);
  EXPECT_EQ(r.frame.id, 0x40u);  // CAN_ERR_BUSOFF

  r = parse_ok("(1.000000) can0 123#1122334455667788_F\r\n");  // len8_dlc suffix
  EXPECT_EQ(r.frame.len, 8);
  r = parse_ok("(1795249950.846187) can0 300#3810000000000000 R");  // as asc2log writes it
  EXPECT_EQ(r.frame.len, 8);
  EXPECT_EQ(r.frame.data[0], 0x38);
  r = parse_ok("(1.000000) can0 123#R2 T");
  EXPECT_TRUE(r.rtr);
  EXPECT_EQ(r.frame.len, 2);
}

TEST(CandumpLine, RejectsMalformedLines) {
  EXPECT_NE(parse_err(""), "");
  EXPECT_NE(parse_err("1436509052.249713 vcan0 044#00"), "");      // no parentheses
  EXPECT_NE(parse_err("(1436509052) vcan0 044#00"), "");           // no fraction
  EXPECT_NE(parse_err("(1.5) vcan0"), "");                         // no frame
  EXPECT_NE(parse_err("(1.5) vcan0 0440#00"), "");                 // 4-digit ID
  EXPECT_NE(parse_err("(1.5) vcan0 844#00"), "");                  // standard ID > 0x7FF
  EXPECT_NE(parse_err("(1.5) vcan0 044#0"), "");                   // odd hex digits
  EXPECT_NE(parse_err("(1.5) vcan0 044#GG"), "");                  // not hex
  EXPECT_NE(parse_err("(1.5) vcan0 044#001122334455667788"), "");  // 9 bytes
  EXPECT_NE(parse_err("(1.5) vcan0 044##100"), "");                // CAN FD
  EXPECT_NE(parse_err("(1.5) vcan0 G44#00"), "");
  EXPECT_NE(parse_err("(1.5) vcan0 123#R9"), "");
  EXPECT_NE(parse_err("(1.5) vcan0 123#1122 X"), "");  // unknown trailing field
  EXPECT_NE(parse_err("(1.5) vcan0 123#1122_"), "");
}

// Hostile input: 12 digits of seconds overflowed int64 nanoseconds (UB; the timestamp
// wrapped to a negative value without sanitizers).
TEST(CandumpLine, TimestampBeyondInt64NanosecondsIsAnError) {
  EXPECT_NE(parse_err("(9223372037.0) can0 123#"), "");
  EXPECT_NE(parse_err("(999999999999.999999) can0 123#"), "");
  EXPECT_NE(parse_err("(9223372036.854775808) can0 123#"), "");
  // The largest representable time still parses, exactly.
  const auto r = parse_ok("(9223372036.854775807) can0 123#");
  EXPECT_EQ(r.t_ns, INT64_MAX);
  EXPECT_GE(parse_ok("(9223372036.0) can0 123#").t_ns, 0);
}

TEST(CandumpLine, FormatMatchesCandumpAndRoundTrips) {
  p::CandumpRecord r;
  r.t_ns = 1436509052249713999;  // sub-microsecond part is truncated like candump
  r.iface = "can0";
  r.frame.id = 0x44;
  r.frame.len = 3;
  r.frame.data[0] = 0x0a;
  r.frame.data[1] = 0xff;
  r.frame.data[2] = 0x10;
  EXPECT_EQ(p::format_candump_line(r), "(1436509052.249713) can0 044#0AFF10");
  r.t_ns = 5'000'000;
  r.frame.extended = true;
  r.frame.id = 0x123;
  EXPECT_EQ(p::format_candump_line(r), "(0000000000.005000) can0 00000123#0AFF10");
  r.error_frame = true;
  r.frame.extended = false;
  r.frame.id = 0x4;
  r.frame.len = 8;
  EXPECT_EQ(p::format_candump_line(r), "(0000000000.005000) can0 20000004#0AFF100000000000");

  // Every encoder output survives format -> parse bit-exactly.
  p::Encoder enc({});
  agv::hal::CanFrame xy, hd;
  for (int i = 0; i < 20; ++i) {
    enc.encode_pose({i * 1000.5, -i * 77.7, i * 0.3, 1.0, true}, &xy, &hd);
    for (const agv::hal::CanFrame* f : {&xy, &hd}) {
      p::CandumpRecord w;
      w.t_ns = 1'700'000'000'000'000'000 + i * 1'000'000;
      w.iface = "can0";
      w.frame = *f;
      const p::CandumpRecord back = parse_ok(p::format_candump_line(w));
      EXPECT_EQ(back.t_ns, w.t_ns);
      EXPECT_EQ(back.frame.id, f->id);
      EXPECT_EQ(back.frame.len, f->len);
      EXPECT_EQ(std::memcmp(back.frame.data, f->data, 8), 0);
    }
  }
}

TEST(CandumpFile, WriteReadAndReplay) {
  const std::string path = temp_path("log.txt");
  agv::can::CandumpWriter w;
  std::string err;
  ASSERT_TRUE(w.open(path, &err)) << err;
  agv::hal::CanFrame f;
  f.id = 0x310;
  f.len = 8;
  for (int i = 0; i < 5; ++i) {
    f.data[2] = static_cast<std::uint8_t>(i);
    ASSERT_TRUE(w.write(f, i == 2 ? "can1" : "can0", 1'000'000'000LL + i * 10'000'000LL));
  }
  p::CandumpRecord e;
  e.t_ns = 1'050'000'000;
  e.iface = "can0";
  e.error_frame = true;
  e.frame.id = 0x40;
  e.frame.len = 8;
  ASSERT_TRUE(w.write(e));
  ASSERT_TRUE(w.close());

  std::vector<p::CandumpRecord> recs;
  ASSERT_TRUE(agv::can::read_candump_file(path, &recs, &err)) << err;
  ASSERT_EQ(recs.size(), 6u);

  agv::can::CandumpReplayBus bus(recs, "can0", -1'000'000'000);
  EXPECT_EQ(bus.peek_time_ns(), 0);
  agv::hal::CanFrame r;
  std::vector<int> seen;
  while (bus.receive(&r, 0) == agv::hal::CanStatus::kOk) {
    seen.push_back(r.data[2]);
    EXPECT_EQ(r.t_ns, r.data[2] * 10'000'000LL);
  }
  EXPECT_EQ(seen, (std::vector<int>{0, 1, 3, 4}));  // can1 line skipped
  EXPECT_EQ(bus.stats().rx_error_frames, 1u);
  EXPECT_EQ(bus.receive(&r, 0), agv::hal::CanStatus::kEndOfStream);

  // Filters apply to replay as to a live bus.
  agv::can::CandumpReplayBus filtered(recs);
  const agv::hal::CanFilter none{0x123, 0x7FF, false};
  ASSERT_EQ(filtered.set_filters(&none, 1), agv::hal::CanStatus::kOk);
  EXPECT_EQ(filtered.receive(&r, 0), agv::hal::CanStatus::kEndOfStream);
  std::remove(path.c_str());
}

TEST(CandumpFile, ReportsTheBadLine) {
  const std::string path = temp_path("bad.txt");
  {
    std::ofstream o(path);
    o << "(1.000000) can0 123#00\n\n(2.000000) can0 123#0\n";
  }
  std::vector<p::CandumpRecord> recs;
  std::string err;
  EXPECT_FALSE(agv::can::read_candump_file(path, &recs, &err));
  EXPECT_NE(err.find(":3:"), std::string::npos) << err;
  EXPECT_FALSE(agv::can::read_candump_file(path + ".missing", &recs, &err));
  std::remove(path.c_str());
}

TEST(CandumpFile, ReplayBusRecordsSentFrames) {
  const std::string path = temp_path("tx.txt");
  agv::can::CandumpWriter w;
  ASSERT_TRUE(w.open(path, nullptr));
  std::vector<p::CandumpRecord> recs(1);
  recs[0].t_ns = 7'000'000'000;
  recs[0].iface = "can0";
  recs[0].frame.id = 0x310;
  recs[0].frame.len = 8;
  agv::can::CandumpReplayBus bus(recs);
  bus.attach_tx_log(&w, "can0");
  agv::hal::CanFrame r;
  ASSERT_EQ(bus.receive(&r, 0), agv::hal::CanStatus::kOk);
  p::Encoder enc({});
  agv::hal::CanFrame v;
  enc.encode_velocity({0.5, 0.1, true}, &v);
  EXPECT_EQ(bus.send(v), agv::hal::CanStatus::kOk);
  ASSERT_TRUE(w.close());
  std::vector<p::CandumpRecord> out;
  ASSERT_TRUE(agv::can::read_candump_file(path, &out, nullptr));
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].t_ns, 7'000'000'000);  // stamped with the replay time
  EXPECT_EQ(out[0].frame.id, 0x302u);
  EXPECT_EQ(bus.sent().size(), 1u);
  std::remove(path.c_str());
}
