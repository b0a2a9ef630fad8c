#include "agv/http/diag_route.hpp"

namespace agv::app {

bool diag_body_too_large(std::string_view content_length, bool has_transfer_encoding) {
  if (has_transfer_encoding) return true;
  if (content_length.empty()) return false;
  if (content_length.size() > 19) return true;  // beyond any 64-bit count
  std::uint64_t n = 0;
  for (const char c : content_length) {
    if (c < '0' || c > '9') return true;
    n = n * 10 + static_cast<std::uint64_t>(c - '0');
  }
  return n > kDiagMaxBodyBytes;
}

DiagRoute route_diag_request(const DiagRequestHead& h) {
  // Refusals first, in the order that costs the client least to learn: a browser retries a 503.
  if (h.busy) return DiagRoute::kBusy;
  if (h.method != "GET" && h.method != "HEAD") return DiagRoute::kMethodNotAllowed;
  if (diag_body_too_large(h.content_length, h.has_transfer_encoding)) {
    return DiagRoute::kBodyTooLarge;
  }
  // Exact paths only: nothing is served from the file system, so there is nothing to normalise
  // and "/./metrics" or "/metrics/" are simply unknown.
  if (h.path == "/") return DiagRoute::kPage;
  if (h.path == "/api/status.json") return DiagRoute::kStatus;
  if (h.path == "/api/map.json") return DiagRoute::kMap;
  if (h.path == "/metrics") return DiagRoute::kMetrics;
  if (h.path == "/frame.png") return DiagRoute::kFrame;
  return DiagRoute::kNotFound;
}

int diag_route_status(DiagRoute route) {
  switch (route) {
    case DiagRoute::kNotFound:
      return 404;
    case DiagRoute::kMethodNotAllowed:
      return 405;
    case DiagRoute::kBodyTooLarge:
      return 413;
    case DiagRoute::kBusy:
      return 503;
    default:
      return 200;
  }
}

}  // namespace agv::app
