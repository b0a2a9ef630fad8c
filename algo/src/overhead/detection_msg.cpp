#include "agv/overhead/detection_msg.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <nlohmann/json.hpp>

#include "../vda5050/json_nesting.hpp"
#include "agv/overhead/tag_code.hpp"

namespace agv::overhead {
namespace {

using nlohmann::json;

// The message is three levels deep (object, tags[], tag{}, corners[], corner[]).
constexpr int kMaxDepth = 6;
constexpr std::uint64_t kCodeMask = (std::uint64_t{1} << 36) - 1;

const char* level_name(SearchLevel l) {
  switch (l) {
    case SearchLevel::kTrack:
      return "track";
    case SearchLevel::kArea:
      return "area";
    case SearchLevel::kFull:
      return "full";
  }
  return "full";
}

// Reads one field; a reason other than kNone stops the decode.
class Reader {
 public:
  explicit Reader(const json& obj) : obj_(obj) {}
  MsgReason reason = MsgReason::kNone;

  const json* field(const char* name) {
    if (reason != MsgReason::kNone) return nullptr;
    const auto it = obj_.find(name);
    if (it == obj_.end()) return fail(MsgReason::kMissingField);
    return &*it;
  }
  std::int64_t integer(const char* name, std::int64_t lo, std::int64_t hi) {
    const json* v = field(name);
    if (!v) return lo;
    if (!v->is_number_integer()) return fail(MsgReason::kWrongType), lo;
    // Unsigned values above int64's range read as negative here and are refused by lo.
    const std::int64_t x = v->is_number_unsigned() && v->get<std::uint64_t>() > INT64_MAX
                               ? -1
                               : v->get<std::int64_t>();
    if (x < lo || x > hi) return fail(MsgReason::kOutOfRange), lo;
    return x;
  }
  std::uint64_t unsigned_int(const char* name, std::uint64_t hi) {
    const json* v = field(name);
    if (!v) return 0;
    if (!v->is_number_unsigned()) return fail(MsgReason::kWrongType), 0;
    const std::uint64_t x = v->get<std::uint64_t>();
    if (x > hi) return fail(MsgReason::kOutOfRange), 0;
    return x;
  }
  double number(const json& v, double lo, double hi) {
    if (reason != MsgReason::kNone) return lo;
    if (!v.is_number()) return fail(MsgReason::kWrongType), lo;
    const double x = v.get<double>();
    if (!std::isfinite(x)) return fail(MsgReason::kNonFinite), lo;
    if (x < lo || x > hi) return fail(MsgReason::kOutOfRange), lo;
    return x;
  }
  double number(const char* name, double lo, double hi) {
    const json* v = field(name);
    return v ? number(*v, lo, hi) : lo;
  }
  bool boolean(const char* name) {
    const json* v = field(name);
    if (v && !v->is_boolean()) fail(MsgReason::kWrongType);
    return v && v->is_boolean() && v->get<bool>();
  }
  const json* fail(MsgReason r) {
    if (reason == MsgReason::kNone) reason = r;
    return nullptr;
  }

 private:
  const json& obj_;
};

MsgReason read_level(const json* v, SearchLevel* out) {
  if (!v) return MsgReason::kMissingField;
  if (!v->is_string()) return MsgReason::kWrongType;
  const std::string& s = v->get_ref<const std::string&>();
  for (SearchLevel l : {SearchLevel::kTrack, SearchLevel::kArea, SearchLevel::kFull}) {
    if (s == level_name(l)) return (*out = l, MsgReason::kNone);
  }
  return MsgReason::kOutOfRange;
}

MsgReason read_tag(const json& j, MsgTag* out) {
  if (!j.is_object()) return MsgReason::kWrongType;
  Reader r(j);
  TagObservation& t = out->tag;
  t.id = static_cast<std::uint32_t>(r.integer("id", 0, kTag36h11Count - 1));
  t.code = r.unsigned_int("code", kCodeMask);
  t.hamming = static_cast<int>(r.integer("hamming", 0, 36));
  t.margin = static_cast<int>(r.integer("margin", -36, 36));
  t.restricted = r.boolean("restricted");
  t.contrast = r.number("contrast", 0.0, 255.0);
  t.corner_sigma_px = r.number("sigma_px", 0.0, kMaxCornerSigmaPx);
  const json* corners = r.field("corners_px");
  if (corners && (!corners->is_array() || corners->size() != 4)) r.fail(MsgReason::kWrongType);
  for (std::size_t i = 0; corners && r.reason == MsgReason::kNone && i < 4; ++i) {
    const json& c = (*corners)[i];
    if (!c.is_array() || c.size() != 2) return MsgReason::kWrongType;
    t.corners_px[i].x = r.number(c[0], -kMaxCornerPx, kMaxCornerPx);
    t.corners_px[i].y = r.number(c[1], -kMaxCornerPx, kMaxCornerPx);
  }
  if (r.reason != MsgReason::kNone) return r.reason;
  return read_level(r.field("level"), &out->level);
}

MsgReason decode_object(const json& j, const std::vector<std::string>& camera_ids,
                        DetectionMsg* out) {
  if (!j.is_object()) return MsgReason::kNotObject;
  Reader r(j);
  if (r.integer("v", 0, INT64_MAX) != kDetectionMsgVersion && r.reason == MsgReason::kNone)
    return MsgReason::kBadVersion;
  const json* cam = r.field("camera");
  if (cam && !cam->is_string()) return MsgReason::kWrongType;
  out->t_ns = r.integer("t_ns", 0, INT64_MAX);
  out->seq = r.unsigned_int("seq", UINT64_MAX);
  const json* tags = r.field("tags");
  if (r.reason != MsgReason::kNone) return r.reason;
  out->camera_id = cam->get<std::string>();
  if (out->camera_id.size() > kMaxCameraIdChars ||
      std::find(camera_ids.begin(), camera_ids.end(), out->camera_id) == camera_ids.end())
    return MsgReason::kUnknownCamera;
  if (!tags->is_array()) return MsgReason::kWrongType;
  if (tags->size() > kMaxDetectionMsgTags) return MsgReason::kTooManyTags;
  out->tags.resize(tags->size());
  for (std::size_t i = 0; i < tags->size(); ++i) {
    const MsgReason why = read_tag((*tags)[i], &out->tags[i]);
    if (why != MsgReason::kNone) return why;
  }
  return MsgReason::kNone;
}

}  // namespace

const char* reason_name(MsgReason r) {
  switch (r) {
    case MsgReason::kNone:
      return "none";
    case MsgReason::kTooLarge:
      return "too_large";
    case MsgReason::kTooDeep:
      return "too_deep";
    case MsgReason::kNotJson:
      return "not_json";
    case MsgReason::kNotObject:
      return "not_object";
    case MsgReason::kBadVersion:
      return "bad_version";
    case MsgReason::kMissingField:
      return "missing_field";
    case MsgReason::kWrongType:
      return "wrong_type";
    case MsgReason::kNonFinite:
      return "non_finite";
    case MsgReason::kOutOfRange:
      return "out_of_range";
    case MsgReason::kUnknownCamera:
      return "unknown_camera";
    case MsgReason::kTooManyTags:
      return "too_many_tags";
  }
  return "unknown";
}

std::string encode_detections(const DetectionMsg& msg) {
  json tags = json::array();
  for (const MsgTag& m : msg.tags) {
    const TagObservation& t = m.tag;
    json corners = json::array();
    for (const Vec2& c : t.corners_px) corners.push_back({c.x, c.y});
    tags.push_back({{"id", t.id},
                    {"code", t.code},
                    {"hamming", t.hamming},
                    {"margin", t.margin},
                    {"restricted", t.restricted},
                    {"contrast", t.contrast},
                    {"sigma_px", t.corner_sigma_px},
                    {"corners_px", std::move(corners)},
                    {"level", level_name(m.level)}});
  }
  const json j = {{"v", kDetectionMsgVersion},
                  {"camera", msg.camera_id},
                  {"t_ns", msg.t_ns},
                  {"seq", msg.seq},
                  {"tags", std::move(tags)}};
  return j.dump();
}

MsgReason decode_detections(std::string_view text, const std::vector<std::string>& camera_ids,
                            DetectionMsg* out) {
  *out = DetectionMsg{};
  MsgReason why = MsgReason::kNone;
  if (text.size() > kMaxDetectionMsgBytes) {
    why = MsgReason::kTooLarge;
  } else if (!vda5050::detail::nesting_within(text, kMaxDepth)) {
    why = MsgReason::kTooDeep;
  } else {
    const json j = json::parse(text.begin(), text.end(), nullptr, false);
    why = j.is_discarded() ? MsgReason::kNotJson : decode_object(j, camera_ids, out);
  }
  if (why != MsgReason::kNone) *out = DetectionMsg{};
  return why;
}

}  // namespace agv::overhead
