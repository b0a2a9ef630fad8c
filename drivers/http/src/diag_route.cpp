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
  if (h.path == "/site.svg") return DiagRoute::kSite;
  if (diag_camera_index(h.path) >= 0) return DiagRoute::kCamera;
  return DiagRoute::kNotFound;
}

int diag_camera_index(std::string_view path) {
  constexpr std::string_view kPrefix = "/camera/", kSuffix = ".png";
  if (path.size() <= kPrefix.size() + kSuffix.size() || path.substr(0, kPrefix.size()) != kPrefix ||
      path.substr(path.size() - kSuffix.size()) != kSuffix) {
    return -1;
  }
  const std::string_view digits =
      path.substr(kPrefix.size(), path.size() - kPrefix.size() - kSuffix.size());
  if (digits.size() > 3 || (digits.size() > 1 && digits[0] == '0')) return -1;
  int index = 0;
  for (const char c : digits) {
    if (c < '0' || c > '9') return -1;
    index = index * 10 + (c - '0');
  }
  return index;
}

int diag_route_status(DiagRoute route) {
  switch (route) {
    case DiagRoute::kNotFound:
    case DiagRoute::kSite:
    case DiagRoute::kCamera:
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
