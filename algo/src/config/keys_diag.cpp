// Key table rows of the diag section (docs/guide/diagnostics.md).
#include <arpa/inet.h>
#include <netinet/in.h>

#include "agv/common/log_escape.hpp"
#include "key_builders.hpp"

namespace agv::config::detail {

void add_diag_keys(std::vector<Key>* k) {
  k->push_back(boolean("diag.enabled", AGV_AT(diag.enabled), false,
                       "`agvloc run` serves the diagnostics page and /metrics. Off: no server "
                       "thread, no socket (`agvloc replay --serve` turns it on for a replay)"));
  k->push_back(text("diag.bind_address", AGV_AT(diag.bind_address), "127.0.0.1",
                    "address the page listens on. The page has no authentication: an address "
                    "other than loopback (127.x, ::1, localhost) also needs `diag.allow_remote`"));
  k->push_back(integer("diag.port", AGV_AT(diag.port), 0, 65535, 8088,
                       {"", "TCP port of the page; 0 = any free port (printed at start)"}));
  k->push_back(boolean("diag.allow_remote", AGV_AT(diag.allow_remote), false,
                       "allow a `bind_address` that is not loopback: anyone on that network sees "
                       "the camera and the pose (read only). Off: such an address is refused by "
                       "the configuration checker"));
  k->push_back(integer("diag.max_clients", AGV_AT(diag.max_clients), 1, 256, 16,
                       {"",
                        "connections served or waiting at once; more are answered 503 at "
                        "once (each waiting one costs a socket and a few hundred bytes)"}));
  k->push_back(integer("diag.threads", AGV_AT(diag.threads), 1, 8, 2,
                       {"",
                        "worker threads of the page (not real-time); more serve more "
                        "browsers at once at more CPU"}));
  k->push_back(number("diag.frame_interval_ms", AGV_AT(diag.frame_interval_ms), 100.0, 60000.0,
                      500.0,
                      {"ms",
                       "the camera image with the detection overlay is encoded at most "
                       "once per interval (all clients share it): ~10-20 ms of one core "
                       "per image"}));
}

namespace {

// The same rule as the server's (firmware diag_server.cpp is_loopback_address): 127/8, ::1 and
// "localhost". inet_pton parses text only (no lookup).
bool loopback(const std::string& a) {
  if (a == "localhost") return true;
  in_addr v4{};
  if (inet_pton(AF_INET, a.c_str(), &v4) == 1) return (ntohl(v4.s_addr) >> 24) == 127;
  in6_addr v6{};
  return inet_pton(AF_INET6, a.c_str(), &v6) == 1 && IN6_IS_ADDR_LOOPBACK(&v6);
}

}  // namespace

void check_diag_values(const Config& cfg, const KeyError& error) {
  // Refused here and not only when the page starts: `agvloc replay --serve` turns the page on
  // whatever diag.enabled says, and --check-config must not pass what the start refuses.
  if (!loopback(cfg.diag.bind_address) && !cfg.diag.allow_remote) {
    error("diag.bind_address",
          "'" + escape_for_log(cfg.diag.bind_address) +
              "' is not loopback and the page has no authentication; set diag.allow_remote: "
              "true to serve it on that network");
  }
}

}  // namespace agv::config::detail
