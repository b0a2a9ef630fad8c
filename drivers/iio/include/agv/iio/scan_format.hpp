// IIO scan-element formats and sample conversion, without libiio or a device (unit-tested on the
// build machine). The kernel describes each buffered channel by a string in
// scan_elements/in_<ch>_type, "[be|le]:[s|u]bits/storagebits[Xrepeat]>>shift", e.g. "le:s16/16>>0"
// (Documentation/ABI/testing/sysfs-bus-iio). A sample is storagebits wide in the given byte
// order; the value is its bits after shifting right by shift, sign-extended for 's'. The value
// in the channel's unit is (raw + offset) * scale (anglvel: rad/s).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace agv::iio {

struct ScanFormat {
  bool big_endian = false;
  bool is_signed = true;
  int bits = 16;          // significant bits, 1..64
  int storage_bits = 16;  // 8, 16, 32 or 64
  int shift = 0;          // right shift before masking, 0 .. storage_bits - bits
  int repeat = 1;         // elements per channel (X suffix); only 1 is used for gyro axes
};

// Parses "le:s16/16>>0". False (and *out untouched) for anything malformed: unknown byte order
// or sign letter, bits out of range, storage not 8/16/32/64, bits + shift > storage.
bool parse_scan_format(const std::string& text, ScanFormat* out);

// Bytes one element occupies in a scan (storage_bits / 8 * repeat); scans align each element
// to its storage size.
inline std::size_t storage_bytes(const ScanFormat& f) {
  return static_cast<std::size_t>(f.storage_bits / 8);
}

// The raw integer of one element at p (storage_bytes(f) bytes): byte order, shift, mask, sign.
std::int64_t decode_raw(const std::uint8_t* p, const ScanFormat& f);

// (raw + offset) * scale: the IIO ABI's conversion to the channel's unit.
inline double apply_scale(std::int64_t raw, double scale, double offset) {
  return (static_cast<double>(raw) + offset) * scale;
}

// Offset of each element in a scan: element i starts at the next multiple of its own storage
// size after element i-1 (the kernel's layout, e.g. s16 x,y,z then s64 timestamp at byte 8).
// offsets[i] for formats[i]; returns the scan size (padded to the largest storage size), or 0
// when n == 0.
std::size_t scan_layout(const ScanFormat* formats, std::size_t n, std::size_t* offsets);

}  // namespace agv::iio
