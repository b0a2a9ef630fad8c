#include "agv/localizer/run_statistics.hpp"

#include <cinttypes>
#include <cstdio>

namespace agv::localizer {

void record_vision(const vision::LandmarkFix& fix, std::int64_t exposure_to_start_ns,
                   std::int64_t vision_ns, VisionStats* vs) {
  ++vs->frames_processed;
  const int s = static_cast<int>(fix.status);
  if (s >= 0 && s < kFixStatusCount) ++vs->by_status[s];
  vs->exposure_to_start_ns.record_ns(exposure_to_start_ns);
  vs->vision_ns.record_ns(vision_ns);
  vs->detect_ns.record_ns(static_cast<std::int64_t>(fix.timings.detect_ms * 1e6));
  if (fix.timings.decode_ms > 0) {
    vs->decode_ns.record_ns(static_cast<std::int64_t>(fix.timings.decode_ms * 1e6));
  }
  if (fix.timings.direction_ms > 0) {
    vs->direction_ns.record_ns(static_cast<std::int64_t>(fix.timings.direction_ms * 1e6));
  }
  if (fix.timings.pose_ms > 0) {
    vs->pose_ns.record_ns(static_cast<std::int64_t>(fix.timings.pose_ms * 1e6));
  }
}

namespace {
void line(std::string* s, const char* name, const LatencyHistogram& h) {
  char buf[200];
  if (h.count() == 0) {
    std::snprintf(buf, sizeof buf, "  %-26s (no samples)\n", name);
  } else {
    std::snprintf(buf, sizeof buf,
                  "  %-26s p50 %8.3f ms  p99 %8.3f ms  max %8.3f ms  (n=%" PRIu64 ")\n", name,
                  static_cast<double>(h.percentile_ns(0.5)) / 1e6,
                  static_cast<double>(h.percentile_ns(0.99)) / 1e6,
                  static_cast<double>(h.max_ns()) / 1e6, h.count());
  }
  *s += buf;
}
}  // namespace

std::string format_statistics(const RunResult& r) {
  std::string s;
  char buf[400];
  const auto& o = r.output;
  const auto& v = r.vision;
  std::snprintf(buf, sizeof buf,
                "statistics:\n  frames: delivered %" PRIu64 ", processed %" PRIu64
                ", dropped (newest-wins) %" PRIu64 ", driver drops %" PRIu64 ", unreadable %" PRIu64
                "\n",
                r.camera.frames_delivered, v.frames_processed, r.frames_dropped_mailbox,
                r.camera.frames_dropped, r.camera.errors);
  s += buf;
  s += "  vision results:";
  for (int i = 0; i < kFixStatusCount; ++i) {
    if (v.by_status[i] == 0) continue;
    std::snprintf(buf, sizeof buf, " %s %" PRIu64,
                  vision::to_string(static_cast<vision::FixStatus>(i)), v.by_status[i]);
    s += buf;
  }
  s += "\n";
  std::snprintf(buf, sizeof buf,
                "  fusion: odometry %" PRIu64 " (rejected %" PRIu64 ", CAN E2E rejected %" PRIu64
                "), fixes fused %" PRIu64 ", gated %" PRIu64 ", too old %" PRIu64
                ", invalid %" PRIu64 ", re-initialisations %" PRIu64 "\n",
                o.odom_samples, o.odom_rejected, r.odometry_rejected_can, o.fixes_fused,
                o.fixes_rejected_gate, o.fixes_rejected_too_old, o.fixes_rejected_invalid,
                o.reinitialisations);
  s += buf;
  const protocol::OdometryCounters& oc = r.odometry_can;
  if (oc.accepted + oc.rejected() > 0) {
    // key=value: the HIL harness reads them (tests/hil, parse_counters).
    std::snprintf(buf, sizeof buf,
                  "  CAN odometry: odom_accepted=%" PRIu64 " odom_lost_frames=%" PRIu64
                  " | rejected: odom_bad_length=%" PRIu64 " odom_bad_crc=%" PRIu64
                  " odom_repeated=%" PRIu64 " odom_counter_jump=%" PRIu64
                  " odom_bad_counter=%" PRIu64 " odom_stale=%" PRIu64 "\n",
                  oc.accepted, oc.lost_frames, oc.bad_length, oc.bad_crc, oc.repeated,
                  oc.counter_jump, oc.bad_counter, oc.stale);
    s += buf;
  }
  if (o.fixes_map_guided > 0) {  // only with a prediction (docs/design/map_identity.md)
    std::snprintf(buf, sizeof buf,
                  "  map-guided fixes: %" PRIu64 " (fused %" PRIu64
                  ", refused while uninitialised or lost %" PRIu64 ")\n",
                  o.fixes_map_guided, o.fixes_map_guided_fused, o.fixes_rejected_not_tracking);
    s += buf;
  }
  std::snprintf(
      buf, sizeof buf,
      "  output: ticks %" PRIu64 ", missed periods %" PRIu64 ", fix-triggered poses %" PRIu64
      ", CAN tx ok %" PRIu64 ", failed %" PRIu64 ", rx %" PRIu64 "\n",
      o.ticks, o.missed_periods, o.fix_poses, o.can_tx_ok, o.can_tx_failed, o.can_rx_frames);
  s += buf;
  if (r.ticks_not_recorded > 0 || r.fixes_not_recorded > 0 || r.odometry_not_recorded > 0) {
    std::snprintf(buf, sizeof buf,
                  "  record FULL: %" PRIu64 " output ticks, %" PRIu64 " vision results and %" PRIu64
                  " received odometry samples were not written to the --out CSVs\n",
                  r.ticks_not_recorded, r.fixes_not_recorded, r.odometry_not_recorded);
    s += buf;
  }
  if (r.can_present) {
    std::snprintf(buf, sizeof buf,
                  "  CAN bus: tx ok %" PRIu64 ", queue full %" PRIu64 ", tx errors %" PRIu64
                  ", rx %" PRIu64 ", rx dropped (receive queue full) %" PRIu64
                  ", error frames %" PRIu64 ", bus-off %" PRIu64 ", restarts %" PRIu64 "\n",
                  r.can.tx_ok, r.can.tx_dropped_queue_full, r.can.tx_errors, r.can.rx_frames,
                  r.can.rx_dropped, r.can.rx_error_frames, r.can.bus_off_count, r.can.restarts);
    s += buf;
  }
  s += r.simulated_time ? " latency (fast replay: only the vision times are measured; the rest "
                          "follow from replay.fix_delay_ms and the output period):\n"
                        : " latency:\n";
  line(&s, "exposure -> vision start", v.exposure_to_start_ns);
  line(&s, "vision (total)", v.vision_ns);
  line(&s, "  detect", v.detect_ns);
  line(&s, "  decode", v.decode_ns);
  line(&s, "  direction", v.direction_ns);
  line(&s, "  pose", v.pose_ns);
  line(&s, "fusion (per period)", o.fusion_ns);
  line(&s, "CAN send (per period)", o.can_send_ns);
  line(&s, "end to end (exposure->CAN)", o.end_to_end_ns);
  line(&s, "output period jitter", o.period_jitter_ns);
  return s;
}

}  // namespace agv::localizer
