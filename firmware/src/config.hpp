// Reading the configuration and map files (size caps, regular files only). The configuration
// itself (Config, parse_config, the key table): agv/config/config.hpp; every key:
// docs/guide/config.md.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "agv/common/landmark.hpp"
#include "agv/config/config.hpp"

namespace agv::config {

// Size caps of the files the localizer reads (docs/design/security.md); larger files are errors.
inline constexpr std::uintmax_t kMaxConfigBytes = 1u << 20;  // 1 MiB
inline constexpr std::uintmax_t kMaxMapBytes = 4u << 20;     // 4 MiB (65535 landmarks ~ 2.6 MB)

// Reads and parses a file (base_dir = the file's directory). The file must be a regular file of
// at most kMaxConfigBytes.
bool load_config(const std::string& path, Config* out, std::vector<std::string>* errors,
                 ConfigUse use = ConfigUse::kLive);
// load_config for the entry points: prints every error as "<who>: config: <error>".
bool load_config_or_report(const std::string& path, const char* who, Config* out,
                           ConfigUse use = ConfigUse::kLive);
// Reads a landmark map file (docs/design/landmark.md; a regular file of at most kMaxMapBytes);
// false with *error naming file and line.
bool load_map_file(const std::string& path, LandmarkMap* map, std::string* error);
// What the YAML alone cannot show but leaves a live run unable to localize: a tag36h11 floor
// without landmark.map (a tag carries only its id), a map id the family does not have. False
// with one line per problem in *errors. map is the configuration's landmark.map (null: none).
bool check_can_localize(const Config& cfg, const LandmarkMap* map,
                        std::vector<std::string>* errors);
// What `agvloc run --check-config` checked, a few lines for the integrator to compare with the
// vehicle: camera and its calibration, landmark family and map, CAN, gyro source, odometry
// correction. map is the loaded landmark.map (null: none). Values as written in YAML.
std::string config_summary(const Config& cfg, const LandmarkMap* map);

}  // namespace agv::config
