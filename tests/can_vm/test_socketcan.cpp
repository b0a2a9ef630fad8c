// Usage: test_socketcan <iface>      (as root, on a kernel with CAN + vcan; see CMakeLists.txt)
// Exercises drivers/socketcan on a real interface: tx/rx, filters, kernel timestamps, error
// frames (injected through a raw socket, which vcan delivers to error-frame subscribers), a full
// transmit queue (tc tbf qdisc + small SO_SNDBUF), and recovery across `ip link set down/up`.
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "agv/can/socketcan.hpp"
#include "agv/protocol/codec.hpp"

using agv::can::SocketCanBus;
using agv::can::SocketCanConfig;
using agv::hal::CanBusState;
using agv::hal::CanFilter;
using agv::hal::CanFrame;
using agv::hal::CanStatus;

namespace {

int g_fail = 0, g_pass = 0, g_skip = 0;
std::string g_if;

std::int64_t mono_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}
void sleep_ms(int ms) {
  timespec ts{ms / 1000, (ms % 1000) * 1'000'000L};
  nanosleep(&ts, nullptr);
}

// A check inside a test: prints and records a failure; returns cond.
bool check(bool cond, const char* test, const char* fmt, ...) {
  if (!cond) {
    char buf[512];
    va_list ap;
    va_start(ap, fmt);
    std::vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    std::printf("FAIL %s: %s\n", test, buf);
    std::fflush(stdout);
  }
  return cond;
}

void result(const char* test, bool ok) {
  if (ok) {
    std::printf("PASS %s\n", test);
    ++g_pass;
  } else {
    ++g_fail;
  }
  std::fflush(stdout);
}

void skip(const char* test, const char* why) {
  std::printf("SKIP %s: %s\n", test, why);
  ++g_skip;
  std::fflush(stdout);
}

int sh(const std::string& cmd) {
  const int rc = std::system((cmd + " >/dev/null 2>&1").c_str());
  return rc;
}

SocketCanConfig cfg(int sndbuf = 0) {
  SocketCanConfig c;
  c.iface = g_if;
  c.sndbuf_bytes = sndbuf;
  c.reopen_backoff_min_ns = 20'000'000;
  c.reopen_backoff_max_ns = 200'000'000;
  return c;
}

CanFrame frame(std::uint32_t id, bool ext, std::uint8_t len, std::uint8_t seed) {
  CanFrame f;
  f.id = id;
  f.extended = ext;
  f.len = len;
  for (int i = 0; i < len; ++i) f.data[i] = static_cast<std::uint8_t>(seed + i * 17);
  return f;
}

bool same(const CanFrame& a, const CanFrame& b) {
  return a.id == b.id && a.extended == b.extended && a.len == b.len &&
         std::memcmp(a.data, b.data, a.len) == 0;
}

void drain(SocketCanBus& b) {
  CanFrame f;
  while (b.receive(&f, 20'000'000) == CanStatus::kOk) {
  }
}

// ---------------------------------------------------------------------------------- tests

void test_open_missing_interface() {
  const char* t = "open_missing_interface";
  SocketCanConfig c = cfg();
  c.iface = "nosuchcan9";
  SocketCanBus b(c);
  bool ok = check(!b.is_open(), t, "opened a non-existent interface");
  ok &= check(b.state() == CanBusState::kDown, t, "state %s, want down", to_string(b.state()));
  ok &= check(std::strlen(b.last_error()) > 0, t, "no last_error");
  ok &= check(b.send(frame(0x100, false, 1, 1)) == CanStatus::kDown, t, "send not kDown");
  CanFrame f;
  ok &= check(b.receive(&f, 1'000'000) == CanStatus::kDown, t, "receive not kDown");
  result(t, ok);
}

void test_tx_rx(SocketCanBus& a, SocketCanBus& b) {
  const char* t = "tx_rx_std_ext";
  bool ok = true;
  drain(b);
  const CanFrame fs[] = {frame(0x123, false, 8, 1), frame(0x1ABCDEF0, true, 5, 2),
                         frame(0x7FF, false, 0, 3)};
  for (const CanFrame& s : fs) {
    const std::int64_t t0 = mono_ns();
    ok &= check(a.send(s) == CanStatus::kOk, t, "send: %s", a.last_error());
    CanFrame r;
    const CanStatus st = b.receive(&r, 500'000'000);
    const std::int64_t t1 = mono_ns();
    ok &= check(st == CanStatus::kOk, t, "receive: %s", to_string(st));
    if (st != CanStatus::kOk) continue;
    ok &= check(same(s, r), t, "frame differs: id %x/%x len %d/%d", s.id, r.id, s.len, r.len);
    ok &= check(r.t_ns >= t0 - 1'000'000 && r.t_ns <= t1, t,
                "timestamp %lld not within [send-1ms, now] = [%lld, %lld] (monotonic?)",
                static_cast<long long>(r.t_ns), static_cast<long long>(t0),
                static_cast<long long>(t1));
  }
  CanFrame r;
  ok &= check(b.receive(&r, 50'000'000) == CanStatus::kTimeout, t, "extra frame received");
  ok &= check(a.stats().tx_ok >= 3, t, "tx_ok %llu", (unsigned long long)a.stats().tx_ok);
  result(t, ok);
}

void test_filters(SocketCanBus& a, SocketCanBus& b) {
  const char* t = "filters";
  bool ok = true;
  drain(b);
  const CanFilter flt[] = {{0x123, 0x7FF, false}, {0x18FF0000, 0x1FFF0000, true}};
  ok &= check(b.set_filters(flt, 2) == CanStatus::kOk, t, "set_filters: %s", b.last_error());
  a.send(frame(0x100, false, 2, 1));      // rejected: other ID
  a.send(frame(0x123, true, 2, 2));       // rejected: extended with the same number
  a.send(frame(0x123, false, 2, 3));      // accepted
  a.send(frame(0x18FF1234, true, 3, 4));  // accepted by mask
  a.send(frame(0x18FE1234, true, 3, 5));  // rejected
  std::vector<CanFrame> got;
  CanFrame r;
  while (b.receive(&r, 100'000'000) == CanStatus::kOk) got.push_back(r);
  ok &= check(got.size() == 2, t, "received %zu frames, want 2", got.size());
  if (got.size() == 2) {
    ok &= check(got[0].id == 0x123 && !got[0].extended, t, "first frame id %x", got[0].id);
    ok &= check(got[1].id == 0x18FF1234 && got[1].extended, t, "second frame id %x", got[1].id);
  }
  ok &= check(b.set_filters(nullptr, 0) == CanStatus::kOk, t, "clearing filters failed");
  a.send(frame(0x100, false, 1, 6));
  ok &= check(b.receive(&r, 200'000'000) == CanStatus::kOk && r.id == 0x100, t,
              "no frame after clearing filters (count 0 must accept all)");
  std::vector<CanFilter> many(agv::hal::kMaxCanFilters + 1);
  ok &= check(b.set_filters(many.data(), many.size()) == CanStatus::kInvalidArgument, t,
              "too many filters accepted");
  result(t, ok);
}

void test_timestamps(SocketCanBus& a, SocketCanBus& b) {
  const char* t = "kernel_timestamps";
  bool ok = true;
  drain(b);
  constexpr int kN = 8;
  constexpr int kGapMs = 5;
  for (int i = 0; i < kN; ++i) {
    a.send(frame(0x200, false, 1, static_cast<std::uint8_t>(i)));
    sleep_ms(kGapMs);
  }
  sleep_ms(20);  // read everything late: user-space stamps would be bunched together
  std::vector<std::int64_t> ts;
  CanFrame r;
  while (b.receive(&r, 50'000'000) == CanStatus::kOk) ts.push_back(r.t_ns);
  ok &= check(ts.size() == kN, t, "received %zu of %d", ts.size(), kN);
  for (std::size_t i = 1; i < ts.size(); ++i) {
    const std::int64_t d = ts[i] - ts[i - 1];
    ok &= check(d >= (kGapMs - 1) * 1'000'000LL, t,
                "gap %zu = %lld ns < %d ms: stamps are not receive-time kernel stamps", i,
                static_cast<long long>(d), kGapMs - 1);
  }
  result(t, ok);
}

int raw_socket() {
  const int s = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  if (s < 0) return -1;
  ifreq ifr{};
  std::strncpy(ifr.ifr_name, g_if.c_str(), IFNAMSIZ - 1);
  if (::ioctl(s, SIOCGIFINDEX, &ifr) < 0) {
    ::close(s);
    return -1;
  }
  sockaddr_can addr{};
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (::bind(s, reinterpret_cast<sockaddr*>(&addr), sizeof addr) < 0) {
    ::close(s);
    return -1;
  }
  return s;
}

bool inject_error(int s, std::uint32_t cls, std::uint8_t d1, std::uint8_t tx, std::uint8_t rx) {
  can_frame cf{};
  cf.can_id = CAN_ERR_FLAG | cls;
  cf.len = CAN_ERR_DLC;
  cf.data[1] = d1;
  cf.data[6] = tx;
  cf.data[7] = rx;
  return ::write(s, &cf, sizeof cf) == static_cast<ssize_t>(sizeof cf);
}

void test_error_frames(SocketCanBus& a, SocketCanBus& b) {
  const char* t = "error_frames";
  const int s = raw_socket();
  if (s < 0) {
    skip(t, "cannot open a raw injection socket");
    return;
  }
  drain(b);
  bool ok = true;
  if (!inject_error(s, CAN_ERR_CRTL | CAN_ERR_CNT, CAN_ERR_CRTL_TX_PASSIVE, 130, 5)) {
    skip(t, "kernel refused to send an error frame from a raw socket");
    ::close(s);
    return;
  }
  // Error frames are consumed inside receive(); a data frame after them ends the wait.
  a.send(frame(0x300, false, 1, 1));
  CanFrame r;
  CanStatus st = b.receive(&r, 300'000'000);
  ok &= check(st == CanStatus::kOk && r.id == 0x300, t, "data frame after error frame: %s",
              to_string(st));
  ok &= check(b.stats().rx_error_frames == 1, t, "rx_error_frames %llu, want 1",
              (unsigned long long)b.stats().rx_error_frames);
  ok &= check(b.state() == CanBusState::kErrorPassive, t, "state %s, want error-passive",
              to_string(b.state()));
  ok &= check(b.error_counters().tx == 130 && b.error_counters().rx == 5, t, "counters tx %u rx %u",
              b.error_counters().tx, b.error_counters().rx);
  ok &= check(b.stats().error_passive_count == 1, t, "error_passive_count");

  inject_error(s, CAN_ERR_BUSOFF, 0, 0, 0);
  st = b.receive(&r, 100'000'000);  // consumes the error frame, then times out
  ok &= check(st == CanStatus::kTimeout, t, "receive after bus-off: %s", to_string(st));
  ok &= check(b.state() == CanBusState::kBusOff, t, "state %s, want bus-off", to_string(b.state()));
  ok &= check(b.stats().bus_off_count == 1, t, "bus_off_count");
  ok &= check(b.send(frame(0x301, false, 1, 1)) == CanStatus::kBusOff, t,
              "send during bus-off not refused");

  inject_error(s, CAN_ERR_RESTARTED, 0, 0, 0);
  b.receive(&r, 100'000'000);
  ok &= check(b.state() == CanBusState::kErrorActive, t, "state %s after restart",
              to_string(b.state()));
  ok &= check(b.send(frame(0x302, false, 1, 1)) == CanStatus::kOk, t, "send after restart");
  // a subscribes too: it must consume the three error frames without returning them as data.
  const std::uint64_t a_rx = a.stats().rx_frames;
  drain(a);
  ok &= check(a.stats().rx_error_frames == 3, t, "a: rx_error_frames %llu, want 3",
              (unsigned long long)a.stats().rx_error_frames);
  ok &= check(a.stats().rx_frames == a_rx + 1, t, "a: %llu data frames, want 1 (0x302)",
              (unsigned long long)(a.stats().rx_frames - a_rx));
  ok &= check(a.state() == CanBusState::kErrorActive, t, "a: state %s", to_string(a.state()));
  ::close(s);
  drain(b);
  result(t, ok);
}

void test_full_tx_queue(SocketCanBus& b) {
  const char* t = "full_tx_queue_never_blocks";
  const bool root = geteuid() == 0;
  bool shaped = false;
  if (root) {
    shaped = sh("tc qdisc replace dev " + g_if + " root tbf rate 8kbit burst 1600 limit 2000") == 0;
  }
  SocketCanBus a(cfg(1));  // kernel raises 1 to its SO_SNDBUF minimum (a few kB)
  bool ok = check(a.is_open(), t, "open: %s", a.last_error());
  constexpr int kN = 20000;
  int n_ok = 0, n_block = 0, n_other = 0, n_slow = 0;
  std::int64_t worst_ns = 0, total_ns = 0;
  for (int i = 0; i < kN && ok; ++i) {
    const std::int64_t t0 = mono_ns();
    const CanStatus st = a.send(frame(0x400, false, 8, static_cast<std::uint8_t>(i)));
    const std::int64_t d = mono_ns() - t0;
    if (d > worst_ns) worst_ns = d;
    if (d > 2'000'000) ++n_slow;
    total_ns += d;
    if (st == CanStatus::kOk)
      ++n_ok;
    else if (st == CanStatus::kWouldBlock)
      ++n_block;
    else
      ++n_other;
  }
  const agv::hal::CanStats s = a.stats();
  std::printf(
      "INFO %s: %d ok, %d would-block, %d other; send time mean %lld ns, worst %lld us, %d sends "
      "> 2 ms; tc shaping %s\n",
      t, n_ok, n_block, n_other, static_cast<long long>(total_ns / kN),
      static_cast<long long>(worst_ns / 1000), n_slow, shaped ? "on" : "off");
  ok &= check(n_other == 0, t, "%d sends failed otherwise (%s)", n_other, a.last_error());
  ok &= check(s.tx_ok == static_cast<std::uint64_t>(n_ok) &&
                  s.tx_dropped_queue_full == static_cast<std::uint64_t>(n_block),
              t, "stats tx_ok %llu dropped %llu do not match the returns",
              (unsigned long long)s.tx_ok, (unsigned long long)s.tx_dropped_queue_full);
  // A blocking send would wait for the shaped link to drain one frame (~16 ms at 8 kbit/s) on
  // nearly every call once the queue is full; an emulated VM may stall any call now and then.
  ok &= check(n_slow <= kN / 100, t, "%d of %d sends took > 2 ms: send blocks", n_slow, kN);
  ok &= check(worst_ns < 1'000'000'000, t, "a send took %lld us: it blocked",
              static_cast<long long>(worst_ns / 1000));
  if (shaped) sh("tc qdisc del dev " + g_if + " root");
  drain(b);
  if (ok && n_block == 0) {
    skip(t, shaped ? "no queue-full return even with tc shaping"
                   : "could not shape the link (no root/tc/sch_tbf); full queue not provoked");
    return;
  }
  if (ok) ok &= check(n_block > 0, t, "no kWouldBlock");
  result(t, ok);
}

template <typename F>
bool wait_for(F cond, int timeout_ms) {
  const std::int64_t end = mono_ns() + timeout_ms * 1'000'000LL;
  while (mono_ns() < end) {
    if (cond()) return true;
    sleep_ms(5);
  }
  return cond();
}

void test_down_up(SocketCanBus& a, SocketCanBus& b) {
  const char* t = "link_down_up_recovery";
  if (geteuid() != 0) {
    skip(t, "needs root for ip link set");
    return;
  }
  drain(b);
  bool ok = true;
  const std::uint64_t ra = a.stats().restarts, rb = b.stats().restarts;
  ok &= check(sh("ip link set " + g_if + " down") == 0, t, "ip link set down failed");
  CanFrame r;
  const CanStatus srx = b.receive(&r, 200'000'000);
  ok &=
      check(srx == CanStatus::kDown, t, "receive on a downed link: %s, want down", to_string(srx));
  const CanStatus stx = a.send(frame(0x500, false, 1, 1));
  ok &= check(stx == CanStatus::kDown, t, "send on a downed link: %s, want down", to_string(stx));
  ok &= check(a.state() == CanBusState::kDown && b.state() == CanBusState::kDown, t,
              "state a %s b %s, want down", to_string(a.state()), to_string(b.state()));
  // While down, receive waits for the next reopen attempt (no spinning) but within its timeout.
  const std::int64_t tr = mono_ns();
  const CanStatus srx2 = b.receive(&r, 100'000'000);
  const std::int64_t wait_ns = mono_ns() - tr;
  ok &= check(srx2 == CanStatus::kDown, t, "second receive while down: %s", to_string(srx2));
  ok &= check(wait_ns >= 5'000'000 && wait_ns < 400'000'000, t,
              "receive while down returned after %lld us (want a wait, bounded by the timeout)",
              static_cast<long long>(wait_ns / 1000));
  // While down, sends keep returning kDown quickly (reopen attempts are rate-limited).
  const std::int64_t t0 = mono_ns();
  for (int i = 0; i < 100; ++i) a.send(frame(0x500, false, 1, 1));
  ok &= check(mono_ns() - t0 < 100'000'000, t, "sends while down are slow");
  ok &= check(sh("ip link set " + g_if + " up") == 0, t, "ip link set up failed");
  const bool back = wait_for(
      [&] {
        if (a.send(frame(0x501, false, 2, 2)) != CanStatus::kOk) return false;
        CanFrame f;
        CanStatus s;
        while ((s = b.receive(&f, 20'000'000)) == CanStatus::kOk) {
          if (f.id == 0x501) return true;
        }
        return false;
      },
      5000);
  ok &= check(back, t, "traffic did not resume within 5 s (a: %s, b: %s)", a.last_error(),
              b.last_error());
  ok &= check(a.stats().restarts == ra + 1 && b.stats().restarts == rb + 1, t,
              "restarts a %llu b %llu, want +1 each", (unsigned long long)a.stats().restarts,
              (unsigned long long)b.stats().restarts);
  ok &= check(a.state() == CanBusState::kErrorActive && b.state() == CanBusState::kErrorActive, t,
              "state after recovery a %s b %s", to_string(a.state()), to_string(b.state()));
  drain(b);
  result(t, ok);
}

// A receiver that does not read for a while (a starved loop) finds every frame sent meanwhile:
// 1000 frames are ~3 s of odometry and gyro at 300 Hz, 3.6 times what the kernel's default
// receive buffer holds. None may be lost, and none is counted as dropped.
void test_receive_queue_holds_a_stall(SocketCanBus& a, SocketCanBus& b) {
  const char* t = "receive_queue_holds_a_stall";
  if (geteuid() != 0) {
    skip(t, "needs root for SO_RCVBUFFORCE");
    return;
  }
  drain(b);
  bool ok = check(b.receive_buffer_bytes() >= 2 * SocketCanConfig{}.rcvbuf_bytes, t,
                  "receive buffer %d bytes, want at least twice the %d requested",
                  b.receive_buffer_bytes(), SocketCanConfig{}.rcvbuf_bytes);
  const std::uint64_t dropped0 = b.stats().rx_dropped;
  constexpr int kFrames = 1000;
  for (int i = 0; i < kFrames; ++i) {
    CanFrame f = frame(0x321, false, 8, static_cast<std::uint8_t>(i));
    f.data[0] = static_cast<std::uint8_t>(i & 0xFF);
    f.data[1] = static_cast<std::uint8_t>(i >> 8);
    CanStatus st;
    int tries = 0;
    while ((st = a.send(f)) == CanStatus::kWouldBlock && ++tries < 1000) sleep_ms(1);
    ok &= check(st == CanStatus::kOk, t, "send %d: %s", i, to_string(st));
    if (i % 50 == 49) sleep_ms(2);  // lets the emulated guest's softirq keep up (backlog 1000)
  }
  int got = 0, in_order = 0;
  CanFrame r;
  while (b.receive(&r, 100'000'000) == CanStatus::kOk) {
    if (r.id != 0x321) continue;
    if (r.data[0] + 256 * r.data[1] == got) ++in_order;
    ++got;
  }
  ok &= check(got == kFrames && in_order == kFrames, t, "received %d (%d in order) of %d", got,
              in_order, kFrames);
  ok &= check(b.stats().rx_dropped == dropped0, t, "%llu counted as dropped",
              static_cast<unsigned long long>(b.stats().rx_dropped - dropped0));
  std::printf("  receive buffer granted: %d bytes\n", b.receive_buffer_bytes());
  result(t, ok);
}

void test_protocol_over_bus(SocketCanBus& a, SocketCanBus& b) {
  const char* t = "protocol_frames_e2e";
  namespace p = agv::protocol;
  drain(b);
  bool ok = true;
  p::ProtocolConfig pc;
  p::Encoder enc(pc);
  p::E2eChecker chk({p::message_def(p::Msg::kPoseXY).data_id, 1});
  for (int i = 0; i < 30; ++i) {
    p::PoseOut pose{1000.0 * i, -5.5 * i, 0.01 * i, 1.0, true};
    agv::hal::CanFrame xy, hd;
    enc.encode_pose(pose, &xy, &hd);
    ok &= check(a.send(xy) == CanStatus::kOk, t, "send xy");
    ok &= check(a.send(hd) == CanStatus::kOk, t, "send heading");
  }
  int checked = 0;
  CanFrame r;
  while (b.receive(&r, 100'000'000) == CanStatus::kOk) {
    if (r.id != pc.base_id) continue;
    const p::E2eStatus s = chk.check(r);
    ok &= check(p::e2e_accepted(s), t, "frame %d rejected: %s", checked, p::to_string(s));
    ++checked;
  }
  ok &= check(checked == 30, t, "checked %d pose frames, want 30", checked);
  result(t, ok);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s <can-interface>   (e.g. vcan0; run as root)\n", argv[0]);
    return 2;
  }
  g_if = argv[1];
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  if (geteuid() == 0 && sh("ip link show " + g_if) != 0) {
    sh("ip link add dev " + g_if + " type vcan");
  }
  if (geteuid() == 0) sh("ip link set " + g_if + " up");

  test_open_missing_interface();
  SocketCanBus a(cfg()), b(cfg());
  if (!a.is_open() || !b.is_open()) {
    std::printf("FAIL open %s: %s\n", g_if.c_str(), a.is_open() ? b.last_error() : a.last_error());
    return 1;
  }
  std::printf("PASS open %s\n", g_if.c_str());
  test_tx_rx(a, b);
  test_filters(a, b);
  test_timestamps(a, b);
  test_error_frames(a, b);
  test_protocol_over_bus(a, b);
  test_receive_queue_holds_a_stall(a, b);
  test_full_tx_queue(b);
  test_down_up(a, b);
  std::printf("SUMMARY %d passed, %d failed, %d skipped\n", g_pass, g_fail, g_skip);
  return g_fail == 0 ? 0 : 1;
}
