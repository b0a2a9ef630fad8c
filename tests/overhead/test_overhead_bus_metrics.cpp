// /metrics of the tracker fed by detector processes (`run --detections-from-broker`): every
// detections message counted, each refusal under its reason, the tags that moved no track
// (overhead/src/diag.cpp, docs/guide/overhead.md "Diagnostics page and metrics"); the orders and
// the tray boxes likewise.
#include <gtest/gtest.h>

#include <string>

#include "diag.hpp"

namespace agv::overhead_app {
namespace {

bool has(const std::string& text, const std::string& line) {
  return text.find(line + "\n") != std::string::npos;
}

TEST(OverheadBusMetrics, MessagesAndRefusalsByReason) {
  DiagView v;
  v.has_bus = true;
  v.bus.messages = 52;
  v.bus.lost = 3;
  v.bus.dropped_behind = 4;
  v.bus.refused = {{"bad_version", 1}, {"not_json", 2}, {"unknown_camera", 0}};
  v.bus.tags = 90;
  v.bus.unknown_ids = 5;
  v.bus.no_fix = 6;
  v.bus.restricted_refused = 7;
  const std::string t = overhead_metrics_text(v, {});
  EXPECT_TRUE(has(t, "# TYPE agvloc_overhead_detections_refused_total counter")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_messages_total 52")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_refused_total{reason=\"bad_version\"} 1")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_refused_total{reason=\"not_json\"} 2")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_refused_total{reason=\"unknown_camera\"} 0")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_lost_total 3")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_dropped_total 4")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_tags_total 90")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_tags_refused_total{reason=\"unknown_id\"} 5"))
      << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_detections_tags_refused_total{reason=\"no_fix\"} 6")) << t;
  EXPECT_TRUE(
      has(t, "agvloc_overhead_detections_tags_refused_total{reason=\"restricted_decode\"} 7"))
      << t;
}

TEST(OverheadBusMetrics, NotShownWithoutDetectorProcesses) {
  const std::string t = overhead_metrics_text(DiagView{}, {});
  EXPECT_EQ(t.find("agvloc_overhead_detections_"), std::string::npos) << t;
  EXPECT_NE(t.find("agvloc_overhead_ticks_total"), std::string::npos) << t;
}

TEST(OverheadBusMetrics, OrdersAndTheirRefusalsByReason) {
  DiagView v;
  v.has_orders = true;
  v.orders.messages = 6;
  v.orders.routes_set = 2;
  v.orders.duplicates = 1;
  v.orders.refused = {{"malformed", 1}, {"not_stitched", 2}, {"stale_update", 0}};
  const std::string t = overhead_metrics_text(v, {});
  EXPECT_TRUE(has(t, "agvloc_overhead_orders_messages_total 6")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_orders_routes_set_total 2")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_orders_routes_cleared_total 0")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_orders_duplicates_total 1")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_orders_refused_total{reason=\"malformed\"} 1")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_orders_refused_total{reason=\"not_stitched\"} 2")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_orders_refused_total{reason=\"stale_update\"} 0")) << t;
  EXPECT_EQ(overhead_metrics_text(DiagView{}, {}).find("agvloc_overhead_orders_"),
            std::string::npos);
}

// The live run's tray boxes: what the tracks did with them, and each refusal under its reason.
TEST(OverheadBusMetrics, TrayBoxesAndTheirRefusalsByReason) {
  DiagView v;
  v.has_tray = true;
  v.tray.applied = 470;
  v.tray.gated = 2;
  v.tray.refused = {{"sides_hidden", 12}, {"uncertain_prediction", 6}, {"no_outline", 0}};
  const std::string t = overhead_metrics_text(v, {});
  EXPECT_TRUE(has(t, "agvloc_overhead_tray_boxes_total{result=\"applied\"} 470")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_tray_boxes_total{result=\"gated\"} 2")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_tray_refused_total{reason=\"sides_hidden\"} 12")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_tray_refused_total{reason=\"uncertain_prediction\"} 6")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_tray_refused_total{reason=\"no_outline\"} 0")) << t;
  EXPECT_TRUE(has(t, "agvloc_overhead_tray_tag_disagree_total 0")) << t;
  EXPECT_EQ(overhead_metrics_text(DiagView{}, {}).find("agvloc_overhead_tray_"), std::string::npos);
}

}  // namespace
}  // namespace agv::overhead_app
