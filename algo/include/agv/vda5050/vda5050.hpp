// VDA 5050 messages of a position provider (docs/guide/vda5050.md): the localizer's tick mapped
// onto agvPosition / mobileRobotPosition and velocity, the visualization, connection and state
// messages, and the initPosition / initializePosition instant action parsed and checked. Pure:
// text in, text out; time is an argument (ns since the Unix epoch), so the same tick always gives
// the same bytes. Versions 2.0.0, 2.1.0 and 3.0.0; their differences are in one place
// (encode.cpp), and the instantActions key of 2.0.0 masters in parse.cpp.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "agv/localizer/localizer.hpp"

namespace agv::vda5050 {

enum class Version : std::uint8_t { k2_0_0, k2_1_0, k3_0_0 };
// "2.0.0" / "2.1.0" / "3.0.0"; false for anything else.
bool parse_version(std::string_view text, Version* out);
const char* version_string(Version v);

struct Identity {
  Version version = Version::k2_1_0;
  std::string interface_name = "uagv";
  std::string manufacturer;
  std::string serial_number;
  std::string map_id;  // the one map agvloc localizes in (its landmark map)
};

// interfaceName/v<major>/manufacturer/serialNumber/<topic>, the layout of the spec's section 6.
std::string topic(const Identity& id, std::string_view leaf);

// The position fields a fleet control reads, in SI units (the localizer works in mm).
struct Position {
  double x_m = 0.0;
  double y_m = 0.0;
  double theta_rad = 0.0;  // wrapped to [-pi, pi]
  bool initialized = false;
  double localization_score = 0.0;  // [0, 1]
  double deviation_range_m = 0.0;   // 3 sigma of the position; < 0 = not known (omitted)
  double vx_mps = 0.0;              // vehicle frame: forward
  double vy_mps = 0.0;  // always 0: a differential or car-like vehicle has no side speed
  double omega_radps = 0.0;
};

// localizationScore reaches 0 when 3 sigma of the position reaches this (a pose 10 cm uncertain is
// no better than none for docking); 1 at sigma 0.
inline constexpr double kScoreZeroAtDeviationMm = 100.0;
// Dead reckoning (no landmark fused lately) caps the score: the pose is extrapolated, not seen.
inline constexpr double kDeadReckoningScoreCap = 0.5;

// The mapping (docs/guide/vda5050.md "Field mapping"): initialized when the filter is initialised,
// not lost, and the status frame's health is OK or DEGRADED; deviationRange = 3 sigma_position in
// m; localizationScore = clamp(1 - 3 sigma / kScoreZeroAtDeviationMm, 0, 1), capped at
// kDeadReckoningScoreCap when dead reckoning, 0 when not initialized.
Position map_tick(const localizer::TickRecord& tick);

// ISO 8601 UTC with milliseconds ("2026-11-27T19:46:05.123Z"), truncated toward the past.
// Negative times give the epoch.
std::string iso8601_utc_ms(std::int64_t t_ns);

enum class ConnectionState : std::uint8_t { kOnline, kOffline, kConnectionBroken };

// Each returns one JSON message. header_id: per topic, incremented by the caller per message
// sent. reference_state_header_id: 3.0.0 only (the newest state message's headerId, 0 if none).
std::string encode_visualization(const Identity& id, std::uint32_t header_id, std::int64_t t_ns,
                                 const Position& p, std::uint32_t reference_state_header_id);
std::string encode_connection(const Identity& id, std::uint32_t header_id, std::int64_t t_ns,
                              ConnectionState s);

enum class ActionStatus : std::uint8_t { kFinished, kFailed };
struct ActionResult {
  std::string action_id;
  std::string action_type;
  ActionStatus status = ActionStatus::kFailed;
  std::string result_description;  // the named reason when failed
};
// One entry of a state message's errors[]: errorType, errorLevel (WARNING or FATAL; sent as
// given), errorDescription, errorReferences (referenceKey, referenceValue).
struct StateError {
  std::string type;
  std::string level = "WARNING";
  std::string description;
  std::vector<std::pair<std::string, std::string>> references;
};
// A state message answering instant actions: the position fields agvloc owns, actionStates and
// errors; the fields of the vehicle controller (order, nodes, battery, safety) neutral
// (docs/guide/vda5050.md "Answering initPosition").
std::string encode_state(const Identity& id, std::uint32_t header_id, std::int64_t t_ns,
                         const Position& p, const std::vector<ActionResult>& actions,
                         const std::vector<StateError>& errors = {});

// Why a message or an action was refused. Every value has a name (reason_name).
enum class Reason : std::uint8_t {
  kNone,
  kTooLarge,          // beyond kMaxMessageBytes
  kTooDeep,           // nesting beyond kMaxDepth
  kNotJson,           // syntax error
  kNotObject,         // top level is not an object
  kMissingField,      // a required header or action field is absent
  kWrongType,         // a field of the wrong JSON type
  kWrongVersion,      // major version not the configured one
  kWrongTarget,       // manufacturer / serialNumber not ours
  kTooManyActions,    // beyond kMaxActions
  kMissingParameter,  // initPosition without x, y, theta or mapId
  kDuplicateParameter,
  kNonFinite,      // not a finite number
  kOutOfRange,     // |x|, |y| beyond kMaxCoordinateM or |theta| beyond pi
  kUnknownMap,     // mapId not the configured map
  kStringTooLong,  // an id beyond kMaxIdChars
};
const char* reason_name(Reason r);

inline constexpr std::size_t kMaxMessageBytes = 64 * 1024;
inline constexpr int kMaxDepth = 16;
inline constexpr std::size_t kMaxActions = 64;
inline constexpr std::size_t kMaxIdChars = 256;
inline constexpr double kMaxCoordinateM = 100'000.0;  // the CAN pose range is far smaller

struct InitPosition {
  std::string action_id;
  std::string action_type;  // initPosition (2.1.0) or initializePosition (3.0.0)
  double x_m = 0.0;
  double y_m = 0.0;
  double theta_rad = 0.0;
  std::string map_id;
  std::string last_node_id;  // reported back by the vehicle controller, not used by agvloc
};

struct ParsedActions {
  Reason message_reason = Reason::kNone;  // the whole message refused (nothing else is set)
  std::vector<InitPosition> accepted;     // in message order
  std::vector<ActionResult> refused;      // our action type, refused (answer FAILED)
  std::size_t not_ours = 0;               // other action types: the vehicle controller's
};

// Parses an instantActions message for id's version: accepts initPosition (2.x) or
// initializePosition (3.0.0) with finite x, y, theta in range and mapId == id.map_id; every other
// action type is left to the vehicle controller (counted in not_ours). The actions are read from
// `actions`; for 2.0.0 from `instantActions` when `actions` is absent (docs/guide/vda5050.md).
// Never throws.
ParsedActions parse_instant_actions(const Identity& id, std::string_view text);

}  // namespace agv::vda5050
