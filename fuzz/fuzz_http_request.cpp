// The diagnostics page's request decisions (drivers/http/src/diag_route.cpp): the HTTP library
// (libmicrohttpd) parses the bytes within its per-connection memory limit, then hands the method,
// path and headers to this function, which decides every answer. Input: a raw request head; the
// first byte's low bit says the server is at its limit of requests in progress. Properties: never
// throws; busy is always 503; only GET and HEAD reach a page; a body of no stated length, a
// Content-Length that is not a decimal number or over 1 kB never reaches a page; only the five
// exact paths are served.
#include <algorithm>
#include <string>
#include <string_view>

#include "agv/http/diag_route.hpp"
#include "fuzz_check.hpp"

namespace a = agv::app;

namespace {

std::string_view header_value(std::string_view head, std::string_view name) {
  std::size_t pos = 0;
  while ((pos = head.find("\r\n", pos)) != std::string_view::npos) {
    pos += 2;
    if (head.substr(pos, name.size()) == name && head.substr(pos + name.size(), 2) == ": ") {
      const std::size_t start = pos + name.size() + 2;
      const std::size_t end = head.find("\r\n", start);
      return head.substr(start, end == std::string_view::npos ? end : end - start);
    }
  }
  return {};
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string_view text = agv::fuzz::as_text(data, size);
  a::DiagRequestHead h;
  h.busy = size > 0 && (data[0] & 1);
  const std::string_view head = text.empty() ? text : text.substr(1);
  const std::size_t sp1 = head.find(' ');
  h.method = head.substr(0, sp1);
  if (sp1 != std::string_view::npos) {
    const std::size_t sp2 = head.find(' ', sp1 + 1);
    std::string_view target =
        head.substr(sp1 + 1, sp2 == std::string_view::npos ? sp2 : sp2 - sp1 - 1);
    h.path = target.substr(0, target.find('?'));  // as the library: the query apart
  }
  h.content_length = header_value(head, "Content-Length");
  h.has_transfer_encoding = !header_value(head, "Transfer-Encoding").empty();
  const a::DiagRoute r = a::route_diag_request(h);
  const int status = a::diag_route_status(r);
  FUZZ_CHECK(status == 200 || status == 404 || status == 405 || status == 413 || status == 503,
             "unexpected status");
  if (h.busy) {
    FUZZ_CHECK(r == a::DiagRoute::kBusy, "busy not refused");
    return 0;
  }
  const bool get = h.method == "GET" || h.method == "HEAD";
  if (!get) FUZZ_CHECK(r == a::DiagRoute::kMethodNotAllowed, "a method other than GET/HEAD");
  if (status == 200) {
    FUZZ_CHECK(get && !h.has_transfer_encoding, "a body of no stated length reached a page");
    // By value, not by length: "01000" is 1000 bytes (leading zeros are valid HTTP).
    std::size_t length = 0;
    for (const char c : h.content_length) {
      FUZZ_CHECK(c >= '0' && c <= '9', "Content-Length");
      length = std::min<std::size_t>(length * 10 + static_cast<std::size_t>(c - '0'), 1u << 20);
    }
    FUZZ_CHECK(length <= a::kDiagMaxBodyBytes, "a Content-Length over 1 kB reached a page");
    FUZZ_CHECK(h.path == "/" || h.path == "/api/status.json" || h.path == "/api/map.json" ||
                   h.path == "/metrics" || h.path == "/frame.png",
               "a path other than the five served");
  }
  return 0;
}
