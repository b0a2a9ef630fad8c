// What the diagnostics page answers to a request, decided from the request line and headers alone
// (no I/O, no library): the HTTP library calls it once the headers are in, before any body is
// read. Kept apart so that it can be fuzzed (fuzz/fuzz_http_request.cpp) and tested without a
// socket.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

namespace agv::app {

// The page needs no request body: any beyond this is refused (413).
constexpr std::size_t kDiagMaxBodyBytes = 1024;

enum class DiagRoute : std::uint8_t {
  kPage,     // GET /
  kStatus,   // GET /api/status.json
  kMap,      // GET /api/map.json
  kMetrics,  // GET /metrics
  kFrame,    // GET /frame.png
  kSite,     // GET /site.svg (agvloc-overhead: the site map with the fleet)
  kCamera,   // GET /camera/<index>.png (agvloc-overhead: a ceiling camera's view)
  kNotFound,
  kMethodNotAllowed,  // 405 with Allow: GET, HEAD
  kBodyTooLarge,      // 413
  kBusy,              // 503: more requests in progress than diag.max_clients
};

struct DiagRequestHead {
  std::string_view method;
  std::string_view path;            // without the query string
  std::string_view content_length;  // "" when absent
  bool has_transfer_encoding = false;
  bool busy = false;  // the server is at its limit of requests in progress
};

// A body beyond kDiagMaxBodyBytes, one whose length is not given in advance (Transfer-Encoding),
// or a Content-Length that is not a plain decimal number.
bool diag_body_too_large(std::string_view content_length, bool has_transfer_encoding);

DiagRoute route_diag_request(const DiagRequestHead& head);

// The index in "/camera/<index>.png": one to three decimal digits, no sign, no leading zero
// (so each camera has exactly one path); -1 for any other path.
int diag_camera_index(std::string_view path);

// The status code the route is answered with (200 for the pages; a kFrame without a camera frame
// is answered 503 by the server). kSite and kCamera are 404 unless the handler serves them (only
// agvloc-overhead does, and it answers 404 for an index that is not one of its cameras).
int diag_route_status(DiagRoute route);

}  // namespace agv::app
