// The page's answers to what is not a plain GET (docs/guide/diagnostics.md "Requests"): HEAD is a
// GET without the body, any other method 405, a body over 1 kB (or of no stated length) 413 before
// it is read, whatever the method.
#include <gtest/gtest.h>
#include <sys/socket.h>
#include <unistd.h>

#include <string>

#include "../support/loopback_client.hpp"
#include "diag_handoff.hpp"
#include "diag_server.hpp"

namespace agv::app {
namespace {

// Sends raw bytes, returns everything read until the server closes (or 20 s pass).
std::string exchange(int port, const std::string& request) {
  const int fd = test::connect_loopback(port, 20);
  if (fd < 0) return "";
  ::send(fd, request.data(), request.size(), MSG_NOSIGNAL);
  std::string out = test::read_until_closed(fd);  // closed, reset after the answer, or the timeout
  ::close(fd);
  return out;
}

int status_of(const std::string& response) {
  if (response.rfind("HTTP/1.1 ", 0) != 0 || response.size() < 12) return 0;
  return std::stoi(response.substr(9, 3));
}

std::string header_of(const std::string& response, const std::string& name) {
  const auto p = response.find("\r\n" + name + ": ");
  if (p == std::string::npos) return "";
  const auto start = p + 4 + name.size();
  return response.substr(start, response.find("\r\n", start) - start);
}

std::string body_of(const std::string& response) {
  const auto p = response.find("\r\n\r\n");
  return p == std::string::npos ? "" : response.substr(p + 4);
}

class DiagRequests : public ::testing::Test {
 protected:
  void SetUp() override {
    cfg_.diag.port = 0;
    server_ = std::make_unique<DiagServer>(cfg_, nullptr, handoff_, frames_, "test");
    std::string error;
    if (!server_->start(&error)) GTEST_SKIP() << error;  // built without libmicrohttpd
  }
  void TearDown() override {
    if (server_) server_->stop();
  }
  int port() const { return server_->port(); }

  config::Config cfg_;
  DiagHandoff handoff_;
  FrameTap frames_;
  std::unique_ptr<DiagServer> server_;
};

TEST_F(DiagRequests, HeadIsAGetWithoutTheBody) {
  const std::string get = exchange(port(), "GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n");
  const std::string head = exchange(port(), "HEAD /metrics HTTP/1.1\r\nHost: x\r\n\r\n");
  ASSERT_EQ(status_of(get), 200) << get;
  ASSERT_EQ(status_of(head), 200) << head;
  EXPECT_EQ(header_of(head, "Content-Type"), header_of(get, "Content-Type"));
  EXPECT_FALSE(header_of(get, "Content-Length").empty());
  EXPECT_TRUE(body_of(head).empty()) << head;
  EXPECT_EQ(status_of(exchange(port(), "HEAD /nothing HTTP/1.1\r\nHost: x\r\n\r\n")), 404);
}

TEST_F(DiagRequests, GetWithABodyOverOneKilobyteIs413) {
  const std::string body(2000, 'b');
  const std::string r = exchange(port(), "GET /metrics HTTP/1.1\r\nHost: x\r\nContent-Length: " +
                                             std::to_string(body.size()) + "\r\n\r\n" + body);
  EXPECT_EQ(status_of(r), 413) << r;
  // Announced, not sent: refused on the header alone (nothing waits for 100 MB).
  EXPECT_EQ(status_of(exchange(port(),
                               "GET / HTTP/1.1\r\nHost: x\r\nContent-Length: "
                               "104857600\r\n\r\n")),
            413);
  // A length that is not a number is malformed before it is large: the HTTP library answers 400.
  const int bad_length =
      status_of(exchange(port(), "GET / HTTP/1.1\r\nHost: x\r\nContent-Length: 1x\r\n\r\n"));
  EXPECT_TRUE(bad_length == 400 || bad_length == 413) << bad_length;
  EXPECT_EQ(status_of(exchange(port(),
                               "GET / HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: "
                               "chunked\r\n\r\n5\r\nhello\r\n0\r\n\r\n")),
            413);
  // A small one is ignored (the page reads no body).
  EXPECT_EQ(status_of(exchange(port(),
                               "GET /metrics HTTP/1.1\r\nHost: x\r\nContent-Length: "
                               "10\r\n\r\n0123456789")),
            200);
}

TEST_F(DiagRequests, OtherMethodsAre405BeforeTheirBodyIsRead) {
  for (const char* method : {"POST", "PUT", "DELETE", "PATCH", "OPTIONS"}) {
    const std::string r = exchange(port(), std::string(method) +
                                               " /metrics HTTP/1.1\r\nHost: x\r\n"
                                               "Content-Length: 104857600\r\n\r\n");
    EXPECT_EQ(status_of(r), 405) << method << "\n" << r;
    EXPECT_EQ(header_of(r, "Allow"), "GET, HEAD") << method;
  }
}

}  // namespace
}  // namespace agv::app
