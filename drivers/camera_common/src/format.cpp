#include <algorithm>
#include <sstream>

#include "agv/camera/common.hpp"

namespace agv::camera {

std::string fourcc_to_string(std::uint32_t f) {
  std::string s;
  for (int i = 0; i < 4; ++i) {
    const char ch = static_cast<char>((f >> (8 * i)) & 0xFF);
    s.push_back(ch >= 32 && ch < 127 ? ch : '?');
  }
  while (!s.empty() && s.back() == ' ') s.pop_back();
  return s;
}

std::vector<std::uint32_t> acceptable_formats(hal::PixelFormatPreference pref) {
  const std::vector<std::uint32_t> gray = {kFourccGrey, kFourccR8};
  const std::vector<std::uint32_t> yuv = {kFourccNv12, kFourccYu12, kFourccYuyv};
  switch (pref) {
    case hal::PixelFormatPreference::kGray:
      return gray;
    case hal::PixelFormatPreference::kYuv:
      return yuv;
    case hal::PixelFormatPreference::kAuto:
      break;
  }
  std::vector<std::uint32_t> all = gray;
  all.insert(all.end(), yuv.begin(), yuv.end());
  for (std::uint32_t f : {kFourccRgb888, kFourccBgr888, kFourccV4l2Bgr24, kFourccV4l2Rgb24}) {
    all.push_back(f);
  }
  return all;
}

std::uint32_t choose_format(hal::PixelFormatPreference pref,
                            const std::vector<std::uint32_t>& offered, std::uint32_t forced) {
  if (forced != 0) {
    const bool ok = std::find(offered.begin(), offered.end(), forced) != offered.end() &&
                    choose_format(hal::PixelFormatPreference::kAuto, {forced}) != 0;
    return ok ? forced : 0;
  }
  for (std::uint32_t f : acceptable_formats(pref)) {
    if (std::find(offered.begin(), offered.end(), f) != offered.end()) return f;
  }
  return 0;
}

bool gray_layout(std::uint32_t fourcc, int w, int h, int stride, GrayLayout* out,
                 std::string* error) {
  auto fail = [&](const std::string& msg) {
    if (error) {
      std::ostringstream e;
      e << fourcc_to_string(fourcc) << " " << w << "x" << h << " stride " << stride << ": " << msg;
      *error = e.str();
    }
    return false;
  };
  if (w <= 0 || h <= 0) return fail("non-positive size");
  const std::size_t rows = static_cast<std::size_t>(h);
  const std::size_t pitch = static_cast<std::size_t>(stride);
  GrayLayout l;
  l.stride_bytes = stride;
  if (fourcc == kFourccGrey || fourcc == kFourccR8) {
    if (stride < w) return fail("stride shorter than a row");
    l.in_place = true;
    l.min_bytes = pitch * (rows - 1) + static_cast<std::size_t>(w);
  } else if (fourcc == kFourccNv12 || fourcc == kFourccYu12) {
    if (stride < w) return fail("stride shorter than a row");
    if (w % 2 != 0 || h % 2 != 0) return fail("4:2:0 needs even width and height");
    l.in_place = true;
    // Y plane, then chroma of half the rows (NV12: one interleaved plane of full pitch;
    // YU12: two planes of half pitch) -> 3/2 of the Y plane either way.
    l.min_bytes = pitch * rows * 3 / 2;
  } else if (fourcc == kFourccYuyv) {
    if (stride < 2 * w) return fail("stride shorter than a row (2 bytes per pixel)");
    if (w % 2 != 0) return fail("YUYV needs an even width");
    l.in_place = false;
    l.min_bytes = pitch * (rows - 1) + 2 * static_cast<std::size_t>(w);
  } else if (fourcc == kFourccRgb888 || fourcc == kFourccBgr888 || fourcc == kFourccV4l2Bgr24 ||
             fourcc == kFourccV4l2Rgb24) {
    if (stride < 3 * w) return fail("stride shorter than a row (3 bytes per pixel)");
    l.in_place = false;
    l.min_bytes = pitch * (rows - 1) + 3 * static_cast<std::size_t>(w);
  } else {
    return fail("unsupported pixel format");
  }
  *out = l;
  return true;
}

void yuyv_to_gray(const std::uint8_t* src, int src_stride, int w, int h, std::uint8_t* dst,
                  int dst_stride) {
  for (int r = 0; r < h; ++r) {
    const std::uint8_t* s = src + static_cast<std::ptrdiff_t>(r) * src_stride;
    std::uint8_t* d = dst + static_cast<std::ptrdiff_t>(r) * dst_stride;
    for (int c = 0; c < w; ++c) d[c] = s[2 * c];
  }
}

void rgb24_to_gray(const std::uint8_t* src, int src_stride, int w, int h, bool r_first,
                   std::uint8_t* dst, int dst_stride) {
  const int ir = r_first ? 0 : 2, ib = r_first ? 2 : 0;
  for (int r = 0; r < h; ++r) {
    const std::uint8_t* s = src + static_cast<std::ptrdiff_t>(r) * src_stride;
    std::uint8_t* d = dst + static_cast<std::ptrdiff_t>(r) * dst_stride;
    for (int c = 0; c < w; ++c, s += 3) {
      d[c] = static_cast<std::uint8_t>((77 * s[ir] + 150 * s[1] + 29 * s[ib] + 128) >> 8);
    }
  }
}

bool convert_to_gray(std::uint32_t fourcc, const std::uint8_t* src, int src_stride, int w, int h,
                     std::uint8_t* dst, int dst_stride) {
  if (fourcc == kFourccYuyv) {
    yuyv_to_gray(src, src_stride, w, h, dst, dst_stride);
  } else if (fourcc == kFourccBgr888 || fourcc == kFourccV4l2Rgb24) {
    rgb24_to_gray(src, src_stride, w, h, true, dst, dst_stride);
  } else if (fourcc == kFourccRgb888 || fourcc == kFourccV4l2Bgr24) {
    rgb24_to_gray(src, src_stride, w, h, false, dst, dst_stride);
  } else {
    return false;
  }
  return true;
}

}  // namespace agv::camera
