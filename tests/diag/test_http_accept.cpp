// The HTTP server accepts a connection only once its request has started to arrive: a socket that
// connects and says nothing takes no connection slot (so it can neither crowd out nor be mistaken
// for a normal client), and one that sends its request is answered at once.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <thread>

#include "agv/http/http_server.hpp"

namespace agv::app {
namespace {

int connect_loopback(int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  if (fd < 0) return -1;
  timeval tv{10, 0};
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

std::string read_all(int fd) {
  std::string out;
  char buf[1024];
  for (;;) {
    const ssize_t n = ::recv(fd, buf, sizeof buf, 0);
    if (n <= 0) return out;
    out.append(buf, static_cast<std::size_t>(n));
  }
}

TEST(HttpAccept, SilentSocketTakesNoSlotAndARequestIsAnsweredAtOnce) {
  HttpServer server(HttpServerSettings{}, [](DiagRoute, HttpAnswer* a) { a->body = "ok\n"; });
  std::string error;
  if (!server.start(&error)) GTEST_SKIP() << error;  // a build without libmicrohttpd
  using Clock = std::chrono::steady_clock;
  const int silent = connect_loopback(server.port());
  ASSERT_GE(silent, 0);
  const auto t_connect = Clock::now();
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const auto open_while_silent = server.counters().open;
  const double waited_s = std::chrono::duration<double>(Clock::now() - t_connect).count();
  // The kernel hands a silent connection over after about 3 s at the earliest (the deferral, then
  // the handshake's retransmission): a test thread held off the CPU that long cannot judge.
  if (waited_s < 2.0) {
    EXPECT_EQ(open_while_silent, 0u) << "a connection that sent nothing was accepted";
  }
  const int talking = connect_loopback(server.port());
  ASSERT_GE(talking, 0);
  const std::string get = "GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n";
  ASSERT_EQ(::send(talking, get.data(), get.size(), MSG_NOSIGNAL),
            static_cast<ssize_t>(get.size()));
  const std::string answer = read_all(talking);
  EXPECT_EQ(answer.rfind("HTTP/1.1 200", 0), 0u) << answer;
  ::close(talking);
  // The silent socket, once it speaks, is a normal client.
  ASSERT_EQ(::send(silent, get.data(), get.size(), MSG_NOSIGNAL), static_cast<ssize_t>(get.size()));
  EXPECT_EQ(read_all(silent).rfind("HTTP/1.1 200", 0), 0u);
  ::close(silent);
  server.stop();
}

}  // namespace
}  // namespace agv::app
