// Builders for the key table rows (keys_*.cpp). Each takes the key's storage as an accessor
// made by AGV_AT(member path), usable on Config and const Config, so a row names its field once.
#pragma once

#include <cmath>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>
#include <vector>

#include "agv/common/geometry.hpp"
#include "agv/config/keys.hpp"

#define AGV_AT(member) \
  [](auto& cfg_) -> auto& { return cfg_.member; }

namespace agv::config::detail {

struct Doc {
  const char* unit;
  const char* text;
};

inline Key base(const char* name, KeyType type, double lo, double hi, Value def, Doc d) {
  Key k;
  k.name = name;
  k.type = type;
  k.lo = lo;
  k.hi = hi;
  k.def = std::move(def);
  k.unit = d.unit;
  k.doc = d.text;
  return k;
}

// A double field stored as written.
template <typename Ref>
Key number(const char* name, Ref ref, double lo, double hi, double def, Doc d) {
  Key k = base(name, KeyType::kNumber, lo, hi, def, d);
  k.get = [ref](const Config& c) { return Value{static_cast<double>(ref(c))}; };
  k.set = [ref](Config& c, const Value& v) { ref(c) = std::get<double>(v); };
  return k;
}

// Milliseconds in YAML, an int64 nanosecond field in the struct.
template <typename Ref>
Key ms_as_ns(const char* name, Ref ref, double lo, double hi, double def, const char* text) {
  Key k = base(name, KeyType::kNumber, lo, hi, def, {"ms", text});
  k.get = [ref](const Config& c) { return Value{static_cast<double>(ref(c)) / 1e6}; };
  k.set = [ref](Config& c, const Value& v) { ref(c) = std::llround(std::get<double>(v) * 1e6); };
  return k;
}

// Degrees in YAML (unit given: deg, deg/s, ...), radians in the struct.
template <typename Ref>
Key deg_as_rad(const char* name, Ref ref, double lo, double hi, double def, Doc d) {
  Key k = base(name, KeyType::kNumber, lo, hi, def, d);
  k.get = [ref](const Config& c) { return Value{rad_to_deg(ref(c))}; };
  k.set = [ref](Config& c, const Value& v) { ref(c) = deg_to_rad(std::get<double>(v)); };
  return k;
}

// Any integral field (int, int64, size_t, uint32).
template <typename Ref>
Key integer(const char* name, Ref ref, std::int64_t lo, std::int64_t hi, std::int64_t def, Doc d,
            KeyType type = KeyType::kInteger) {
  Key k = base(name, type, static_cast<double>(lo), static_cast<double>(hi), def, d);
  k.get = [ref](const Config& c) { return Value{static_cast<std::int64_t>(ref(c))}; };
  k.set = [ref](Config& c, const Value& v) {
    using T = std::remove_reference_t<decltype(ref(c))>;
    ref(c) = static_cast<T>(std::get<std::int64_t>(v));
  };
  return k;
}

template <typename Ref>
Key can_id(const char* name, Ref ref, std::int64_t def, const char* text) {
  return integer(name, ref, 0, 0x7FF, def, {"", text}, KeyType::kCanId);
}

template <typename Ref>
Key boolean(const char* name, Ref ref, bool def, const char* text) {
  Key k = base(name, KeyType::kBool, 0, 0, def, {"", text});
  k.get = [ref](const Config& c) { return Value{static_cast<bool>(ref(c))}; };
  k.set = [ref](Config& c, const Value& v) { ref(c) = std::get<bool>(v); };
  return k;
}

template <typename Ref>
Key text(const char* name, Ref ref, const char* def, const char* doc) {
  Key k = base(name, KeyType::kString, 0, 0, std::string(def), {"", doc});
  k.get = [ref](const Config& c) { return Value{std::string(ref(c))}; };
  k.set = [ref](Config& c, const Value& v) { ref(c) = std::get<std::string>(v); };
  return k;
}

// A std::string field restricted to choices.
template <typename Ref>
Key choice(const char* name, Ref ref, std::vector<std::string> choices, const char* def,
           const char* doc) {
  Key k = text(name, ref, def, doc);
  k.type = KeyType::kChoice;
  k.choices = std::move(choices);
  return k;
}

// An enum field: choices[i] names values[i].
template <typename Ref, typename E>
Key enumeration(const char* name, Ref ref, std::vector<std::pair<std::string, E>> values,
                const char* def, const char* doc) {
  Key k = base(name, KeyType::kChoice, 0, 0, std::string(def), {"", doc});
  for (const auto& [n, e] : values) k.choices.push_back(n);
  k.get = [ref, values](const Config& c) {
    for (const auto& [n, e] : values) {
      if (ref(c) == e) return Value{n};
    }
    return Value{std::string("?")};
  };
  k.set = [ref, values](Config& c, const Value& v) {
    for (const auto& [n, e] : values) {
      if (n == std::get<std::string>(v)) ref(c) = e;
    }
  };
  return k;
}

// An enum's name table (config.hpp, landmark.hpp) as enumeration() takes it.
template <typename E, std::size_t N>
std::vector<std::pair<std::string, E>> named(const std::pair<std::string_view, E> (&table)[N]) {
  std::vector<std::pair<std::string, E>> v;
  for (const auto& [n, e] : table) v.emplace_back(std::string(n), e);
  return v;
}

// The rows of each group, in reading order (keys_vehicle.cpp, keys_vision.cpp, keys_fusion.cpp).
void add_vehicle_keys(std::vector<Key>* keys);
void add_vision_keys(std::vector<Key>* keys);
void add_fusion_keys(std::vector<Key>* keys);
void add_replay_keys(std::vector<Key>* keys);
void add_vda5050_keys(std::vector<Key>* keys);         // keys_vda5050.cpp
void add_diag_keys(std::vector<Key>* keys);            // keys_diag.cpp
void add_ranging_camera_keys(std::vector<Key>* keys);  // keys_ranging.cpp

// What the consumers of a section's strings accept beyond the key's type (parse.cpp calls these
// with the keys read): error(key, why) per refusal.
using KeyError = std::function<void(const std::string& key, const std::string& why)>;
void check_vda5050_values(const Config& cfg, const KeyError& error);         // keys_vda5050.cpp
void check_diag_values(const Config& cfg, const KeyError& error);            // keys_diag.cpp
void check_ranging_camera_values(const Config& cfg, const KeyError& error);  // keys_ranging.cpp

}  // namespace agv::config::detail
