#include "agv/iio/scan_format.hpp"

#include <cstdlib>

namespace agv::iio {

namespace {

// Reads a decimal integer at s[*i]; false when there is none.
bool read_int(const std::string& s, std::size_t* i, int* v) {
  std::size_t j = *i;
  int x = 0;
  while (j < s.size() && s[j] >= '0' && s[j] <= '9' && j - *i < 4) x = x * 10 + (s[j++] - '0');
  if (j == *i) return false;
  *i = j;
  *v = x;
  return true;
}

}  // namespace

bool parse_scan_format(const std::string& text, ScanFormat* out) {
  std::string s = text;
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  ScanFormat f;
  if (s.compare(0, 3, "le:") == 0) {
    f.big_endian = false;
  } else if (s.compare(0, 3, "be:") == 0) {
    f.big_endian = true;
  } else {
    return false;
  }
  std::size_t i = 3;
  if (i >= s.size() || (s[i] != 's' && s[i] != 'u')) return false;
  f.is_signed = s[i++] == 's';
  if (!read_int(s, &i, &f.bits) || i >= s.size() || s[i++] != '/') return false;
  if (!read_int(s, &i, &f.storage_bits)) return false;
  if (i < s.size() && s[i] == 'X') {
    ++i;
    if (!read_int(s, &i, &f.repeat) || f.repeat < 1) return false;
  }
  if (s.compare(i, 2, ">>") != 0) return false;
  i += 2;
  if (!read_int(s, &i, &f.shift) || i != s.size()) return false;
  if (f.storage_bits != 8 && f.storage_bits != 16 && f.storage_bits != 32 && f.storage_bits != 64)
    return false;
  if (f.bits < 1 || f.bits + f.shift > f.storage_bits) return false;
  *out = f;
  return true;
}

std::int64_t decode_raw(const std::uint8_t* p, const ScanFormat& f) {
  const int n = f.storage_bits / 8;
  std::uint64_t u = 0;
  for (int k = 0; k < n; ++k) {
    const int byte = f.big_endian ? k : n - 1 - k;  // most significant first
    u = (u << 8) | p[byte];
  }
  u >>= f.shift;
  if (f.bits < 64) {
    u &= (std::uint64_t{1} << f.bits) - 1;
    if (f.is_signed && (u >> (f.bits - 1)) != 0) u |= ~((std::uint64_t{1} << f.bits) - 1);
  }
  return static_cast<std::int64_t>(u);
}

std::size_t scan_layout(const ScanFormat* formats, std::size_t n, std::size_t* offsets) {
  std::size_t pos = 0;
  std::size_t largest = 1;
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t size = storage_bytes(formats[i]);
    if (size > largest) largest = size;
    pos = (pos + size - 1) / size * size;
    offsets[i] = pos;
    pos += size * static_cast<std::size_t>(formats[i].repeat);
  }
  if (n == 0) return 0;
  return (pos + largest - 1) / largest * largest;
}

}  // namespace agv::iio
