// The configuration key table: one record per key, the single source of truth for the checker
// (parse_config), the defaults (test_config proves the struct defaults equal the table) and
// docs/guide/config.md (config_doc(); `agvloc-config-doc > docs/guide/config.md` regenerates it,
// and test_config fails when the committed file differs). A key the code does not read does not
// exist: every record stores into the Config.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <variant>
#include <vector>

#include "agv/config/config.hpp"

namespace agv::config {

enum class KeyType {
  kNumber,   // finite double in [lo, hi]
  kInteger,  // integer in [lo, hi]
  kBool,     // true | false
  kChoice,   // one of choices
  kString,   // any scalar
  kCanId,    // integer in [lo, hi], hi widened to 0x1FFFFFFF by can.extended_ids (read before)
};

// A value in the key's YAML unit (ms, deg): kNumber double, kInteger/kCanId int64, kBool bool,
// kChoice/kString string.
using Value = std::variant<bool, std::int64_t, double, std::string>;

inline constexpr std::int64_t kCanExtendedIdMax = 0x1FFFFFFF;

struct Key {
  std::string name;  // dotted path: "can.odometry.timeout_ms"
  KeyType type = KeyType::kNumber;
  double lo = 0.0, hi = 0.0;  // kNumber, kInteger, kCanId
  std::vector<std::string> choices;
  std::string unit;  // of the YAML value; "" = none
  Value def;         // the default, in the YAML unit (ignored when required_live)
  // Camera calibration: no default; a live configuration must set it (ConfigUse::kLive).
  bool required_live = false;
  std::string doc;  // one line: what the knob trades, and why the default
  // Storage, in the YAML unit: get reads the Config field (ns -> ms, rad -> deg), set writes it
  // (ms -> ns rounded to the nearest ns, deg -> rad) and any field that follows from it.
  std::function<Value(const Config&)> get;
  std::function<void(Config&, const Value&)> set;

  std::string section() const;  // "can.odometry"
  std::string leaf() const;     // "timeout_ms"
};

struct Section {
  std::string path;   // "can.odometry"
  std::string title;  // heading text after the path, e.g. "(docs/guide/can.md)"
  std::string intro;  // prose before the table (verbatim, may be empty)
  // For sections with required_live keys: why they are required, named in the error.
  std::string required_why;
};

// A key that existed once: a configuration that still has it fails naming the replacement.
struct RemovedKey {
  std::string name;
  std::string replacement;
};

// In reading order: a key may depend on a key before it (can.extended_ids before the IDs,
// fusion.estimate_odometry_calibration before the noise keys whose defaults it changes).
const std::vector<Key>& config_keys();
const std::vector<Section>& config_sections();
const std::vector<RemovedKey>& removed_keys();
const Key* find_key(const std::string& name);

// As written in YAML and docs ("0x300", "4.685", "true").
std::string format_value(const Key& key, const Value& v);
// The accepted range as documented ("5..10000", "v_omega, wheels").
std::string format_range(const Key& key);

// docs/guide/config.md, byte for byte.
std::string config_doc();

}  // namespace agv::config
