// The declared input shape of an ONNX model, read from the protobuf bytes directly (ModelProto ->
// graph -> input -> type -> tensor_type -> shape -> dim), so a model made for another window size
// is refused by name before any inference, whatever the inference engine makes of it.
#include <cstdint>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "agv/overhead/tray_net.hpp"

namespace agv::overhead {
namespace onnx_detail {

// One protobuf message's fields, read in order; a malformed buffer sets bad.
class Reader {
 public:
  explicit Reader(std::string_view s) : s_(s) {}
  bool bad = false;
  // Next field: number, wire type, and for length-delimited fields the bytes, for varints the
  // value.
  bool next(std::uint32_t* field, int* wire, std::string_view* bytes, std::uint64_t* value) {
    if (bad || pos_ >= s_.size()) return false;
    std::uint64_t key = 0;
    if (!varint(&key)) return fail();
    *field = static_cast<std::uint32_t>(key >> 3);
    *wire = static_cast<int>(key & 7);
    if (*field == 0) return fail();
    switch (*wire) {
      case 0:
        return varint(value) || fail();
      case 1:
        return skip(8);
      case 2: {
        std::uint64_t n = 0;
        if (!varint(&n) || n > s_.size() - pos_) return fail();
        *bytes = s_.substr(pos_, static_cast<std::size_t>(n));
        pos_ += static_cast<std::size_t>(n);
        return true;
      }
      case 5:
        return skip(4);
      default:
        return fail();
    }
  }

 private:
  bool fail() {
    bad = true;
    return false;
  }
  bool skip(std::size_t n) { return n <= s_.size() - pos_ ? (pos_ += n, true) : fail(); }
  bool varint(std::uint64_t* v) {
    *v = 0;
    for (int shift = 0; shift < 64 && pos_ < s_.size(); shift += 7) {
      const auto b = static_cast<std::uint8_t>(s_[pos_++]);
      *v |= static_cast<std::uint64_t>(b & 0x7f) << shift;
      if (!(b & 0x80)) return true;
    }
    return false;
  }
  std::string_view s_;
  std::size_t pos_ = 0;
};

// The sub-message numbered `field` of msg (the last one), or nothing.
bool sub(std::string_view msg, std::uint32_t field, std::string_view* out) {
  Reader r(msg);
  std::uint32_t f = 0;
  int w = 0;
  std::string_view b;
  std::uint64_t v = 0;
  bool found = false;
  while (r.next(&f, &w, &b, &v)) {
    if (f == field && w == 2) *out = b, found = true;
  }
  return found && !r.bad;
}

struct Input {
  std::string name;
  std::vector<long long> dims;
};

bool parse_input(std::string_view value_info, Input* in) {
  Reader r(value_info);
  std::uint32_t f = 0;
  int w = 0;
  std::string_view b;
  std::uint64_t v = 0;
  std::string_view type;
  while (r.next(&f, &w, &b, &v)) {
    if (f == 1 && w == 2) in->name = std::string(b);
    if (f == 2 && w == 2) type = b;
  }
  std::string_view tensor, shape;
  if (r.bad || !sub(type, 1, &tensor) || !sub(tensor, 2, &shape)) return false;
  Reader d(shape);
  while (d.next(&f, &w, &b, &v)) {
    if (f != 1 || w != 2) continue;
    Reader dim(b);
    std::uint32_t df = 0;
    int dw = 0;
    std::string_view db;
    std::uint64_t dv = 0;
    long long value = -1;
    while (dim.next(&df, &dw, &db, &dv)) {
      if (df == 1 && dw == 0) value = static_cast<long long>(dv);
    }
    if (dim.bad) return false;
    in->dims.push_back(value);
  }
  return !d.bad;
}

}  // namespace onnx_detail

bool onnx_input_shape(const char* data, std::size_t size, std::array<long long, 4>* shape,
                      std::string* why) {
  using namespace onnx_detail;
  auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  if (!data || size == 0 || !shape) return fail("empty model");
  std::string_view graph;
  if (!sub(std::string_view(data, size), 7, &graph)) return fail("not an ONNX model (no graph)");
  Reader r(graph);
  std::uint32_t f = 0;
  int w = 0;
  std::string_view b;
  std::uint64_t v = 0;
  std::set<std::string> initializers;
  std::vector<Input> inputs;
  while (r.next(&f, &w, &b, &v)) {
    if (w != 2) continue;
    if (f == 5) {
      std::string_view name;
      if (sub(b, 8, &name)) initializers.emplace(name);
    } else if (f == 11) {
      Input in;
      if (!parse_input(b, &in)) return fail("not an ONNX model (bad graph input)");
      inputs.push_back(std::move(in));
    }
  }
  if (r.bad) return fail("not an ONNX model (truncated or corrupt)");
  std::vector<const Input*> real;
  for (const Input& in : inputs) {
    if (!initializers.count(in.name)) real.push_back(&in);
  }
  if (real.size() != 1) {
    return fail("the model has " + std::to_string(real.size()) + " inputs, expected one image");
  }
  if (real[0]->dims.size() != 4) {
    return fail("the model's input has " + std::to_string(real[0]->dims.size()) +
                " dimensions, expected 4 (N, C, H, W)");
  }
  for (std::size_t i = 0; i < 4; ++i) (*shape)[i] = real[0]->dims[i];
  return true;
}

}  // namespace agv::overhead
