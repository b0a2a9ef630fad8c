// The one rule for a recording's meta.yaml against `agvloc replay --config` (docs/guide/replay.md):
// a camera key the --config file sets is used, meta.yaml gives the rest; the image size is the
// recording's (its frames have that size).
#pragma once

#include <string>
#include <vector>

#include "agv/config/config.hpp"
#include "agv/recording/recording.hpp"

namespace agv::app {

// The configuration keys meta.yaml carries (image size, intrinsics, mounting, landmark size and,
// in recordings that have it, the landmark family).
const std::vector<std::string>& meta_keys();

// Puts meta's value into *cfg for every meta key that config_keys (the dotted keys the --config
// file sets; empty without --config) does not name. A key both set to different values keeps
// cfg's and adds one line to *lines naming the key, both values and the one used. False with
// *error when --config sets another image size than the recording's (its intrinsics would be of
// another resolution, the frames are not).
bool apply_recording_meta(const recording::Meta& meta, const std::vector<std::string>& config_keys,
                          const std::string& config_name, config::Config* cfg,
                          std::vector<std::string>* lines, std::string* error);

}  // namespace agv::app
