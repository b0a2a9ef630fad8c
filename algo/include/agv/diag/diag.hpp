// Diagnostics of a running localizer (docs/guide/diagnostics.md): what the output loop hands to the
// diagnostics page, and its encodings (JSON for the page, Prometheus text for /metrics). Pure: the
// server thread (firmware/src/diag_server.*) owns the sockets, threads and clocks.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "agv/common/geometry.hpp"
#include "agv/common/landmark.hpp"
#include "agv/hal/can_types.hpp"
#include "agv/localizer/localizer.hpp"
#include "agv/vision/landmark_localizer.hpp"

namespace agv::diag {

// Fixed-capacity history, oldest overwritten: the loop records into it without allocating.
template <typename T, std::size_t N>
struct Ring {
  std::array<T, N> items{};
  std::uint64_t pushed = 0;

  void push(const T& v) {
    items[static_cast<std::size_t>(pushed % N)] = v;
    ++pushed;
  }
  std::size_t size() const { return pushed < N ? static_cast<std::size_t>(pushed) : N; }
  // i = 0 is the oldest kept.
  const T& at(std::size_t i) const {
    const std::uint64_t first = pushed < N ? 0 : pushed - N;
    return items[static_cast<std::size_t>((first + i) % N)];
  }
};

struct FixEntry {
  std::int64_t t_exposure_ns = 0;
  std::int64_t t_arrival_ns = 0;
  vision::FixStatus status = vision::FixStatus::kNoLandmark;
  std::uint32_t landmark_id = 0;
  bool map_verified = false;
  Pose2 vehicle_in_world;  // meaningful only when status == kOk
  double sigma_mm = 0.0;   // sqrt of the larger of the fix's x / y variances
};

struct TrackPoint {
  std::int64_t t_ns = 0;
  double x_mm = 0.0, y_mm = 0.0;
  bool valid = false;
};

// The last fixes the page lists, and the trajectory it draws: 600 points at the 10 Hz hand-off
// rate are the last minute of driving (14 kB copied per hand-off).
inline constexpr std::size_t kLastFixes = 10;
inline constexpr std::size_t kTrackPoints = 600;

// One hand-off from the loop. Trivially copyable, fixed size (~31 kB, most of it the four latency
// histograms): the loop copies it into a slot it only try-locks.
struct Snapshot {
  bool has_tick = false;
  localizer::TickRecord tick;
  localizer::OutputStats stats;
  hal::CanStats can;
  bool can_present = false;
  std::uint64_t frames_dropped = 0;  // camera newest-wins replacements (capture -> vision)
  Ring<FixEntry, kLastFixes> fixes;
  Ring<TrackPoint, kTrackPoints> track;
  // The run is over (replay ended): this is its final state and no newer one will come.
  bool finished = false;
};

// The server's own counters, shown on the page and in /metrics.
struct ServerStats {
  std::uint64_t requests = 0;         // answered with 2xx
  std::uint64_t refused_busy = 0;     // 503: connection limit reached
  std::uint64_t refused_bad = 0;      // 4xx: unknown path, method, oversized request
  std::uint64_t frames_encoded = 0;   // overlay PNGs encoded (rate-limited; cached in between)
  std::uint64_t snapshots_taken = 0;  // snapshots the server took from the loop's slot
  std::uint64_t loop_busy_skips = 0;  // hand-offs the loop skipped because the slot was busy
};

// Fills the loop-side parts of *out (tick, statistics, CAN, fixes and track are copied by the
// caller's recorder); kept here so the firmware and the tests build snapshots alike.
FixEntry fix_entry(const vision::LandmarkMeasurement& fix, std::int64_t t_exposure_ns,
                   std::int64_t t_arrival_ns);
TrackPoint track_point(const localizer::TickRecord& tick);

// Names of the set bits of protocol::fault / protocol::reject (docs/guide/can.md), for the page.
std::string fault_names_json(std::uint16_t faults);
std::string rejection_names_json(std::uint8_t rejections);

// /api/status.json: health, pose with sigma, faults, rejection flags, counters, latencies, the
// last fixes. mode: "run", "replay". Non-finite numbers are written as null.
std::string status_json(const Snapshot& s, const ServerStats& server, const char* mode);
// /api/map.json: the landmarks of the map (may be null: none) and the recent trajectory.
std::string map_json(const LandmarkMap* map, const Snapshot& s);
// /metrics: Prometheus text exposition format 0.0.4 (counters, gauges, histograms in seconds).
std::string metrics_text(const Snapshot& s, const ServerStats& server);

// The histogram bounds of /metrics, seconds (100 us to 2.5 s: output period jitter to a stalled
// end to end). A latency is counted under a bound only when its histogram bucket lies wholly below
// it (exact to one bucket, ~3 %).
inline constexpr std::array<double, 14> kMetricBoundsS = {
    0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5};

// Appends v to out as a JSON number (shortest round-trip form), or null when not finite.
void append_json_number(std::string* out, double v);
// Appends s as a JSON string literal (quoted, escaped).
void append_json_string(std::string* out, const char* s);

}  // namespace agv::diag
