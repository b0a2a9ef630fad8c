// The HTTP server accepts a connection only once its request has started to arrive: a socket that
// connects and says nothing takes no connection slot (so it can neither crowd out nor be mistaken
// for a normal client), and one that sends its request is answered at once.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <thread>

#include "../support/loopback_client.hpp"
#include "agv/http/http_server.hpp"

namespace agv::app {
namespace {

using test::connect_loopback;

TEST(HttpAccept, SilentSocketTakesNoSlotAndARequestIsAnsweredAtOnce) {
  HttpServer server(HttpServerSettings{}, [](DiagRoute, HttpAnswer* a) { a->body = "ok\n"; });
  std::string error;
  if (!server.start(&error)) GTEST_SKIP() << error;  // a build without libmicrohttpd
  using Clock = std::chrono::steady_clock;
  const int silent = connect_loopback(server.port(), 10);
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
  const int talking = connect_loopback(server.port(), 10);
  ASSERT_GE(talking, 0);
  const std::string get = "GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n";
  ASSERT_EQ(::send(talking, get.data(), get.size(), MSG_NOSIGNAL),
            static_cast<ssize_t>(get.size()));
  const std::string answer = test::read_until_closed(talking);
  EXPECT_EQ(answer.rfind("HTTP/1.1 200", 0), 0u) << answer;
  ::close(talking);
  // The silent socket, once it speaks, is a normal client.
  ASSERT_EQ(::send(silent, get.data(), get.size(), MSG_NOSIGNAL), static_cast<ssize_t>(get.size()));
  EXPECT_EQ(test::read_until_closed(silent).rfind("HTTP/1.1 200", 0), 0u);
  ::close(silent);
  server.stop();
}

}  // namespace
}  // namespace agv::app
