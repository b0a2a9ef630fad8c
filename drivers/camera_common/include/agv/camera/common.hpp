// Helpers shared by the live camera drivers (libcamera, V4L2) and the fake camera.
// No device access: everything here is a pure function, unit-tested in tests/camera.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "agv/hal/camera.hpp"

namespace agv::camera {

// ---- configuration ----------------------------------------------------------------------------

// Limits checked by validate_config. Wide enough for any floor camera we expect; they catch
// typos (exposure in ms instead of us, fps 0) before a device is touched.
inline constexpr int kMinSizePx = 16;
inline constexpr int kMaxSizePx = 8192;
inline constexpr double kMinFps = 1.0;
inline constexpr double kMaxFps = 500.0;
inline constexpr int kMinExposureUs = 1;
inline constexpr int kMaxBuffers = 32;

// Empty string when the config is usable; otherwise a message naming the offending field.
// Also rejects an exposure longer than one frame period (the sensor would silently lower fps).
std::string validate_config(const hal::CameraConfig& config);

// ---- pixel formats ----------------------------------------------------------------------------

constexpr std::uint32_t make_fourcc(char a, char b, char c, char d) {
  return static_cast<std::uint32_t>(static_cast<unsigned char>(a)) |
         (static_cast<std::uint32_t>(static_cast<unsigned char>(b)) << 8) |
         (static_cast<std::uint32_t>(static_cast<unsigned char>(c)) << 16) |
         (static_cast<std::uint32_t>(static_cast<unsigned char>(d)) << 24);
}
// Same codes as V4L2 (and libcamera's PixelFormat::fourcc()).
inline constexpr std::uint32_t kFourccGrey = make_fourcc('G', 'R', 'E', 'Y');  // V4L2 Y8
inline constexpr std::uint32_t kFourccR8 = make_fourcc('R', '8', ' ', ' ');    // libcamera R8
inline constexpr std::uint32_t kFourccNv12 = make_fourcc('N', 'V', '1', '2');
inline constexpr std::uint32_t kFourccYu12 = make_fourcc('Y', 'U', '1', '2');  // YUV420 planar
inline constexpr std::uint32_t kFourccYuyv = make_fourcc('Y', 'U', 'Y', 'V');
// Packed 24-bit RGB, last resort (one copy + weighted sum). Byte order in memory:
inline constexpr std::uint32_t kFourccRgb888 =
    make_fourcc('R', 'G', '2', '4');  // libcamera RGB888: B G R
inline constexpr std::uint32_t kFourccBgr888 =
    make_fourcc('B', 'G', '2', '4');  // libcamera BGR888: R G B
inline constexpr std::uint32_t kFourccV4l2Bgr24 = make_fourcc('B', 'G', 'R', '3');  // B G R
inline constexpr std::uint32_t kFourccV4l2Rgb24 = make_fourcc('R', 'G', 'B', '3');  // R G B

std::string fourcc_to_string(std::uint32_t fourcc);

// Formats acceptable under a preference, best first: formats whose Y plane can be used in place
// come before YUYV, which needs a copy; packed RGB (e.g. the vimc test camera) comes last and
// only under kAuto.
std::vector<std::uint32_t> acceptable_formats(hal::PixelFormatPreference pref);
// First entry of acceptable_formats(pref) that `offered` contains; 0 when none. With `forced`
// (non-zero, for tests and odd devices) exactly that format, if offered and acceptable at all.
std::uint32_t choose_format(hal::PixelFormatPreference pref,
                            const std::vector<std::uint32_t>& offered, std::uint32_t forced = 0);

// How to obtain 8-bit gray from one buffer of a negotiated format.
struct GrayLayout {
  bool in_place = false;      // true: the gray image is the buffer's first plane (no copy)
  int stride_bytes = 0;       // in place: row pitch of the Y plane; copy: source row pitch
  std::size_t min_bytes = 0;  // smallest valid buffer (payload) for this format and size
};
// Checks that fourcc/size/stride are consistent; false with *error otherwise.
bool gray_layout(std::uint32_t fourcc, int width_px, int height_px, int stride_bytes,
                 GrayLayout* layout, std::string* error);

// YUYV (Y0 U Y1 V) -> gray, taking every luma byte. dst must hold height rows of dst_stride.
void yuyv_to_gray(const std::uint8_t* src, int src_stride_bytes, int width_px, int height_px,
                  std::uint8_t* dst, int dst_stride_bytes);

// Packed 24-bit RGB -> gray with full-range BT.601 weights (77 R + 150 G + 29 B) / 256.
// r_first: memory order R G B (else B G R).
void rgb24_to_gray(const std::uint8_t* src, int src_stride_bytes, int width_px, int height_px,
                   bool r_first, std::uint8_t* dst, int dst_stride_bytes);

// Copying conversion for a format whose GrayLayout is not in place (YUYV, packed RGB).
// False for formats that need no copy or are unknown.
bool convert_to_gray(std::uint32_t fourcc, const std::uint8_t* src, int src_stride_bytes,
                     int width_px, int height_px, std::uint8_t* dst, int dst_stride_bytes);

// ---- frame sequence ---------------------------------------------------------------------------

// Frames the device numbered but never delivered between the previous delivered frame
// (`last_sequence`, -1 before the first) and this one: the gap in its sequence counter. Computed
// in the counter's own unsigned type, so a counter that wraps (V4L2's and libcamera's 32 bits)
// counts across the wrap.
template <typename Seq>
Seq frames_skipped(std::int64_t last_sequence, Seq sequence) {
  if (last_sequence < 0) return 0;
  const Seq expected = static_cast<Seq>(static_cast<Seq>(last_sequence) + 1u);
  return sequence > expected ? static_cast<Seq>(sequence - expected) : Seq{0};
}

// ---- timestamps -------------------------------------------------------------------------------

// What instant a driver timestamp marks.
enum class TimestampRef {
  kStartOfExposure,  // first row starts exposing (libcamera SensorTimestamp, V4L2 TSTAMP_SRC_SOE)
  kEndOfFrame,       // last row has been received (V4L2 TSTAMP_SRC_EOF, the V4L2 default)
};

// Exposure mid-time of the centre row. A rolling shutter exposes row r from
// t_first + r * readout / (rows - 1); the centre row is half the readout after the first, and its
// exposure midpoint half the exposure after its start. End-of-frame is taken as the end of the
// last row's exposure (transfer delay after that is not observable here and is left to the
// latency calibration).
std::int64_t exposure_mid_ns(std::int64_t t_ns, TimestampRef ref, std::int64_t exposure_ns,
                             std::int64_t readout_ns);

enum class ClockDomain { kMonotonic, kBoottime };

// libcamera documents SensorTimestamp on CLOCK_BOOTTIME, but several pipeline handlers pass the
// V4L2 buffer timestamp (CLOCK_MONOTONIC) through. The two clocks differ only by the time spent
// in suspend, so the domain is decided from the timestamp itself: a fresh timestamp lies a little
// before "now" on its own clock. now_* are read right after the frame completed.
// When the clocks differ by less than `equal_tolerance_ns` the choice does not matter and
// kMonotonic is returned.
ClockDomain guess_clock_domain(std::int64_t t_ns, std::int64_t now_monotonic_ns,
                               std::int64_t now_boottime_ns,
                               std::int64_t equal_tolerance_ns = 1'000'000);

// Converts a timestamp of the given domain to CLOCK_MONOTONIC, using clock readings taken
// together (now_boottime - now_monotonic is the suspend time so far).
std::int64_t to_monotonic_ns(std::int64_t t_ns, ClockDomain domain, std::int64_t now_monotonic_ns,
                             std::int64_t now_boottime_ns);

// Reads CLOCK_MONOTONIC / CLOCK_BOOTTIME (drivers only; algo/ never reads clocks).
std::int64_t monotonic_now_ns();
std::int64_t boottime_now_ns();

}  // namespace agv::camera
