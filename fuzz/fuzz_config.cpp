// The configuration YAML (docs/guide/config.md), read as `agvloc run` reads it. Properties: nothing
// throws or aborts (this build rethrows from parse_config's last-resort catch, so an exception
// is a finding); it is accepted exactly when no error is reported, every error names a key path;
// an accepted live configuration has a usable camera model (finite mm/px) and a valid CAN
// protocol and fusion configuration; whatever is accepted for live use is accepted for replay.
#include <cmath>
#include <string>
#include <vector>

#include "agv/config/config.hpp"
#include "fuzz_check.hpp"

extern "C" int LLVMFuzzerTestOneInput(const unsigned char* data, std::size_t size) {
  const std::string text(agv::fuzz::as_text(data, size));
  agv::config::Config live;
  std::vector<std::string> errors;
  const bool ok = agv::config::parse_config(text, "/etc/agvloc", &live, &errors);
  FUZZ_CHECK(ok == errors.empty(), "accepted=%d with %zu errors", ok, errors.size());
  for (const auto& e : errors) {
    FUZZ_CHECK(!e.empty() && e.find(": ") != std::string::npos, "'%s'", e.c_str());
  }
  if (!ok) return 0;
  // Whatever is accepted for live use is accepted for replay (parsed only then: half the cost).
  agv::config::Config replay;
  std::vector<std::string> replay_errors;
  FUZZ_CHECK(agv::config::parse_config(text, "/etc/agvloc", &replay, &replay_errors,
                                       agv::config::ConfigUse::kReplay),
             "live accepts, replay rejects: %s",
             replay_errors.empty() ? "" : replay_errors.front().c_str());
  const auto& k = live.camera_model.intrinsics;
  FUZZ_CHECK(k.fx >= 1 && k.fy >= 1 && std::isfinite(live.camera_model.mm_per_px()) &&
                 live.camera_model.mm_per_px() > 0,
             "camera model fx %g fy %g", k.fx, k.fy);
  FUZZ_CHECK(
      k.width_px == live.camera.camera.width_px && k.height_px == live.camera.camera.height_px,
      "image size");
  FUZZ_CHECK(agv::protocol::validate(agv::config::protocol_config(live)).empty(), "protocol");
  FUZZ_CHECK(agv::fusion::validate(live.fusion).empty(), "fusion");
  FUZZ_CHECK(live.loop.output_rate_hz >= 1 && live.loop.output_rate_hz <= 1000, "rate");
  return 0;
}
