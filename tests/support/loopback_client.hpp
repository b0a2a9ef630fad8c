// A plain TCP client on 127.0.0.1 for the tests that talk to an HTTP server byte by byte.
#pragma once

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <string>

namespace agv::test {

// A socket connected to the loopback port, each recv giving up after `recv_timeout_s` (0: never);
// -1 when the socket or the connection fails.
inline int connect_loopback(int port, long recv_timeout_s) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return -1;
  timeval tv{recv_timeout_s, 0};
  ::setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  if (::connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof a) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// Everything read until the peer closes, resets, or a recv times out.
inline std::string read_until_closed(int fd) {
  std::string out;
  char buf[4096];
  for (;;) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) return out;
    out.append(buf, static_cast<std::size_t>(n));
  }
}

// GET path over a new connection: the whole answer (headers and body) until the server closes;
// "" when it cannot connect.
inline std::string http_get_raw(int port, const std::string& path, long recv_timeout_s = 0) {
  const int fd = connect_loopback(port, recv_timeout_s);
  if (fd < 0) return "";
  std::string out;
  const std::string req = "GET " + path + " HTTP/1.1\r\nHost: localhost\r\n\r\n";
  if (::send(fd, req.data(), req.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(req.size()))
    out = read_until_closed(fd);
  ::close(fd);
  return out;
}

}  // namespace agv::test
