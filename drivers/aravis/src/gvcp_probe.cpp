#include "gvcp_probe.hpp"

#include <arpa/inet.h>
#include <errno.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstring>

namespace agv::aravis {

namespace {
constexpr std::uint16_t kReadRegCmd = 0x0080;
constexpr std::uint16_t kReadRegAck = 0x0081;
// Bootstrap register "Version", present on every GigE Vision device.
constexpr std::uint32_t kVersionRegister = 0x0000;

std::uint16_t be16(const std::uint8_t* p) {
  return static_cast<std::uint16_t>((static_cast<unsigned>(p[0]) << 8) | p[1]);
}
constexpr int kReadRegSize = 12;

// GVCP READREG of one register: key 0x42, flag "acknowledge required", command, payload length 4,
// request id, address; all big-endian.
void read_register_cmd(std::uint16_t request_id, std::uint32_t address,
                       std::uint8_t out[kReadRegSize]) {
  out[0] = 0x42;
  out[1] = 0x01;
  out[2] = static_cast<std::uint8_t>(kReadRegCmd >> 8);
  out[3] = static_cast<std::uint8_t>(kReadRegCmd & 0xff);
  out[4] = 0;
  out[5] = 4;
  out[6] = static_cast<std::uint8_t>(request_id >> 8);
  out[7] = static_cast<std::uint8_t>(request_id & 0xff);
  for (int i = 0; i < 4; ++i) out[8 + i] = static_cast<std::uint8_t>(address >> (24 - 8 * i));
}

}  // namespace

GvcpProbe::~GvcpProbe() { close(); }

bool GvcpProbe::open(const std::string& ipv4, std::uint16_t port, std::string* error) {
  close();
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(port);
  if (inet_pton(AF_INET, ipv4.c_str(), &addr.sin_addr) != 1) {
    *error = "not an IPv4 address: " + ipv4;
    return false;
  }
  fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd_ < 0) {
    *error = std::string("socket: ") + std::strerror(errno);
    return false;
  }
  // Connected, so that the host's "port unreachable" comes back to this socket as ECONNREFUSED.
  if (connect(fd_, reinterpret_cast<const sockaddr*>(&addr), sizeof addr) != 0) {
    *error = std::string("connect: ") + std::strerror(errno);
    close();
    return false;
  }
  return true;
}

void GvcpProbe::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

GvcpProbe::Result GvcpProbe::send_request() {
  if (fd_ < 0) return Result::kNothing;
  const Result earlier = poll_answers();
  if (earlier != Result::kNothing) return earlier;
  request_id_ = static_cast<std::uint16_t>(request_id_ + 1);
  if (request_id_ == 0) request_id_ = 1;  // 0 is not a valid request id
  std::uint8_t cmd[kReadRegSize];
  read_register_cmd(request_id_, kVersionRegister, cmd);
  if (send(fd_, cmd, sizeof cmd, MSG_NOSIGNAL) < 0 && errno == ECONNREFUSED) {
    return Result::kRefused;
  }
  return Result::kNothing;
}

GvcpProbe::Result GvcpProbe::poll_answers() {
  if (fd_ < 0) return Result::kNothing;
  Result result = Result::kNothing;
  for (;;) {
    std::uint8_t buf[64];
    const ssize_t n = recv(fd_, buf, sizeof buf, 0);
    if (n < 0) {
      if (errno == ECONNREFUSED) return Result::kRefused;
      return result;  // EAGAIN: nothing more
    }
    // Answers to earlier requests count too: the camera was there a moment ago.
    if (n >= kReadRegSize && be16(buf + 2) == kReadRegAck) result = Result::kAnswered;
  }
}

}  // namespace agv::aravis
