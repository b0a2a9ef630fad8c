// /metrics in the Prometheus text exposition format 0.0.4: the run statistics' counters, the
// current pose quality as gauges, and the loop's latency histograms in seconds (Prometheus base
// unit) re-binned from LatencyHistogram's log buckets.
#include <cmath>
#include <cstdio>

#include "agv/diag/diag.hpp"
#include "agv/protocol/codec.hpp"

namespace agv::diag {

namespace {

void header(std::string* out, const char* name, const char* type, const char* help) {
  *out += "# HELP ";
  *out += name;
  *out += ' ';
  *out += help;
  *out += "\n# TYPE ";
  *out += name;
  *out += ' ';
  *out += type;
  *out += '\n';
}

void sample(std::string* out, const char* name, const char* labels, double v) {
  *out += name;
  if (labels && *labels) {
    *out += '{';
    *out += labels;
    *out += '}';
  }
  *out += ' ';
  if (std::isnan(v)) {
    *out += "NaN";
  } else if (std::isinf(v)) {
    *out += v > 0 ? "+Inf" : "-Inf";
  } else {
    append_json_number(out, v);  // Go's ParseFloat reads the shortest round-trip form
  }
  *out += '\n';
}
void sample_u(std::string* out, const char* name, const char* labels, std::uint64_t v) {
  *out += name;
  if (labels && *labels) {
    *out += '{';
    *out += labels;
    *out += '}';
  }
  *out += ' ';
  *out += std::to_string(v);
  *out += '\n';
}

void counter(std::string* out, const char* name, const char* help, std::uint64_t v) {
  header(out, name, "counter", help);
  sample_u(out, name, nullptr, v);
}

void histogram(std::string* out, const char* base, const char* help, const LatencyHistogram& h) {
  header(out, base, "histogram", help);
  const std::string bucket = std::string(base) + "_bucket";
  std::uint64_t cumulative = 0;
  int b = 0;
  for (double bound_s : kMetricBoundsS) {
    const auto bound_ns = static_cast<std::int64_t>(std::llround(bound_s * 1e9));
    // The last raw bucket is open-ended: only +Inf holds it.
    while (b < LatencyHistogram::kBuckets - 1 &&
           LatencyHistogram::bucket_upper_edge_ns(b) <= bound_ns) {
      cumulative += h.bucket_count(b);
      ++b;
    }
    char le[48];
    std::snprintf(le, sizeof le, "le=\"%g\"", bound_s);
    sample_u(out, bucket.c_str(), le, cumulative);
  }
  sample_u(out, bucket.c_str(), "le=\"+Inf\"", h.count());
  sample(out, (std::string(base) + "_sum").c_str(), nullptr, static_cast<double>(h.sum_ns()) / 1e9);
  sample_u(out, (std::string(base) + "_count").c_str(), nullptr, h.count());
}

}  // namespace

std::string metrics_text(const Snapshot& s, const ServerStats& server) {
  std::string o;
  o.reserve(8192);
  const localizer::OutputStats& st = s.stats;
  counter(&o, "agvloc_ticks_total", "Output periods run.", st.ticks);
  counter(&o, "agvloc_missed_periods_total", "Output wake-ups later than one full period.",
          st.missed_periods);
  counter(&o, "agvloc_odometry_samples_total", "Odometry samples given to the filter.",
          st.odom_samples);
  counter(&o, "agvloc_odometry_rejected_total",
          "Odometry samples the filter rejected (time or plausibility).", st.odom_rejected);
  counter(&o, "agvloc_gyro_samples_total", "Gyro samples given to the filter.", st.gyro_samples);
  counter(&o, "agvloc_gyro_rejected_total", "Gyro samples the filter rejected.", st.gyro_rejected);
  counter(&o, "agvloc_fixes_received_total", "Landmark fixes handed to the filter.",
          st.fixes_received);
  counter(&o, "agvloc_fixes_fused_total", "Landmark fixes fused.", st.fixes_fused);
  header(&o, "agvloc_fixes_rejected_total", "counter",
         "Landmark fixes the filter refused, by reason.");
  sample_u(&o, "agvloc_fixes_rejected_total", "reason=\"gate\"", st.fixes_rejected_gate);
  sample_u(&o, "agvloc_fixes_rejected_total", "reason=\"too_old\"", st.fixes_rejected_too_old);
  sample_u(&o, "agvloc_fixes_rejected_total", "reason=\"invalid\"", st.fixes_rejected_invalid);
  sample_u(&o, "agvloc_fixes_rejected_total", "reason=\"not_tracking\"",
           st.fixes_rejected_not_tracking);
  counter(&o, "agvloc_reinitialisations_total", "Filter re-initialisations from a fix.",
          st.reinitialisations);
  header(&o, "agvloc_can_tx_frames_total", "counter", "CAN frames sent by the output, by result.");
  sample_u(&o, "agvloc_can_tx_frames_total", "result=\"ok\"", st.can_tx_ok);
  sample_u(&o, "agvloc_can_tx_frames_total", "result=\"failed\"", st.can_tx_failed);
  counter(&o, "agvloc_can_rx_frames_total", "CAN frames received by the localizer.",
          st.can_rx_frames);
  if (s.can_present) {
    header(&o, "agvloc_can_errors_total", "counter", "CAN bus driver errors, by kind.");
    sample_u(&o, "agvloc_can_errors_total", "kind=\"tx_queue_full\"", s.can.tx_dropped_queue_full);
    sample_u(&o, "agvloc_can_errors_total", "kind=\"tx_error\"", s.can.tx_errors);
    sample_u(&o, "agvloc_can_errors_total", "kind=\"rx_error_frame\"", s.can.rx_error_frames);
    sample_u(&o, "agvloc_can_errors_total", "kind=\"rx_dropped\"", s.can.rx_dropped);
    sample_u(&o, "agvloc_can_errors_total", "kind=\"bus_off\"", s.can.bus_off_count);
    sample_u(&o, "agvloc_can_errors_total", "kind=\"error_passive\"", s.can.error_passive_count);
  }
  counter(&o, "agvloc_camera_frames_dropped_total",
          "Camera frames replaced by a newer one before vision took them.", s.frames_dropped);

  const fusion::PoseEstimate& e = s.tick.estimate;
  header(&o, "agvloc_pose_valid", "gauge",
         "PoseValid of the newest CAN pose frames (0 while LOST or without odometry).");
  sample_u(&o, "agvloc_pose_valid", nullptr, s.tick.pose_valid ? 1 : 0);
  header(&o, "agvloc_pose_initialised", "gauge",
         "1 when the filter has a pose (since the first fix; also while LOST).");
  sample_u(&o, "agvloc_pose_initialised", nullptr, e.valid ? 1 : 0);
  header(&o, "agvloc_health", "gauge", "The CAN status health of the newest tick (one-hot).");
  const protocol::Health h = s.tick.status.health;
  sample_u(&o, "agvloc_health", "state=\"ok\"", h == protocol::Health::kOk ? 1 : 0);
  sample_u(&o, "agvloc_health", "state=\"degraded\"", h == protocol::Health::kDegraded ? 1 : 0);
  sample_u(&o, "agvloc_health", "state=\"lost\"", h == protocol::Health::kLost ? 1 : 0);
  sample_u(&o, "agvloc_health", "state=\"fault\"", h == protocol::Health::kFault ? 1 : 0);
  header(&o, "agvloc_position_sigma_meters", "gauge",
         "1-sigma position uncertainty (largest axis) of the newest pose.");
  sample(&o, "agvloc_position_sigma_meters", nullptr, e.position_sigma_mm / 1000.0);
  header(&o, "agvloc_heading_sigma_radians", "gauge", "1-sigma heading uncertainty.");
  sample(&o, "agvloc_heading_sigma_radians", nullptr, e.heading_sigma_rad);
  header(&o, "agvloc_time_since_fix_seconds", "gauge",
         "Time since the newest fused fix; -1 when none was fused.");
  sample(&o, "agvloc_time_since_fix_seconds", nullptr,
         e.time_since_fix_ns < 0 ? -1.0 : static_cast<double>(e.time_since_fix_ns) / 1e9);
  header(&o, "agvloc_faults", "gauge",
         "Fault bits of the newest CAN status frame (docs/guide/can.md).");
  sample_u(&o, "agvloc_faults", nullptr, s.tick.status.faults);
  header(&o, "agvloc_rejections", "gauge", "Rejection bits of the newest CAN status frame.");
  sample_u(&o, "agvloc_rejections", nullptr, s.tick.status.rejections);

  histogram(&o, "agvloc_end_to_end_seconds",
            "Fix exposure to the first pose frame sent that carries it.", st.end_to_end_ns);
  histogram(&o, "agvloc_period_jitter_seconds", "Output wake-up minus its scheduled time.",
            st.period_jitter_ns);
  histogram(&o, "agvloc_fusion_seconds", "Filter and output policy time of one tick.",
            st.fusion_ns);
  histogram(&o, "agvloc_can_send_seconds", "All CAN sends of one tick.", st.can_send_ns);

  counter(&o, "agvloc_diag_requests_total", "Diagnostics requests answered.", server.requests);
  header(&o, "agvloc_diag_refused_total", "counter", "Diagnostics requests refused, by reason.");
  sample_u(&o, "agvloc_diag_refused_total", "reason=\"busy\"", server.refused_busy);
  sample_u(&o, "agvloc_diag_refused_total", "reason=\"bad_request\"", server.refused_bad);
  counter(&o, "agvloc_diag_frames_encoded_total", "Camera overlay images encoded.",
          server.frames_encoded);
  counter(&o, "agvloc_diag_loop_busy_skips_total",
          "Hand-offs the output loop skipped because the server held the slot.",
          server.loop_busy_skips);
  return o;
}

}  // namespace agv::diag
