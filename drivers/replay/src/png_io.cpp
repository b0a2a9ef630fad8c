#include "agv/recording/png_io.hpp"

#include <png.h>

#include <csetjmp>
#include <cstdio>
#include <memory>
#include <vector>

namespace agv::png {

namespace {

struct FileCloser {
  void operator()(FILE* f) const {
    if (f) std::fclose(f);
  }
};

void on_error(png_structp p, png_const_charp msg) {
  auto* err = static_cast<std::string*>(png_get_error_ptr(p));
  if (err) *err = msg;
  png_longjmp(p, 1);
}
void on_warning(png_structp, png_const_charp) {}

constexpr png_uint_32 kMaxSide = 16384;

}  // namespace

bool read_gray(const std::string& path, cv::Mat* out, std::string* error, int expect_width,
               int expect_height) {
  std::unique_ptr<FILE, FileCloser> f(std::fopen(path.c_str(), "rb"));
  if (!f) {
    *error = path + ": cannot open";
    return false;
  }
  unsigned char sig[8];
  if (std::fread(sig, 1, 8, f.get()) != 8 || png_sig_cmp(sig, 0, 8) != 0) {
    *error = path + ": not a PNG file";
    return false;
  }
  std::string msg;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &msg, on_error, on_warning);
  if (!png) {
    *error = path + ": libpng init failed";
    return false;
  }
  // Refuse oversized headers inside libpng, and bound what ancillary chunks (zTXt, iCCP) may
  // allocate: a few hundred bytes of compressed text must not become megabytes.
  png_set_user_limits(png, kMaxSide, kMaxSide);
  png_set_chunk_malloc_max(png, 1u << 20);
  png_infop info = png_create_info_struct(png);
  // Everything touched after setjmp and read after a longjmp must not live in registers.
  cv::Mat* volatile result = out;
  std::vector<png_bytep> rows;
  if (!info || setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, info ? &info : nullptr, nullptr);
    *error = path + ": corrupt PNG (" + (msg.empty() ? "libpng error" : msg) + ")";
    return false;
  }
  png_init_io(png, f.get());
  png_set_sig_bytes(png, 8);
  png_read_info(png, info);
  const png_uint_32 w = png_get_image_width(png, info);
  const png_uint_32 h = png_get_image_height(png, info);
  const int color = png_get_color_type(png, info);
  if (w == 0 || h == 0 || w > kMaxSide || h > kMaxSide) {
    png_destroy_read_struct(&png, &info, nullptr);
    *error = path + ": unsupported image size";
    return false;
  }
  // Compared before decoding: a small file can declare 16384x16384 (268 MB of pixels).
  if ((expect_width > 0 && w != static_cast<png_uint_32>(expect_width)) ||
      (expect_height > 0 && h != static_cast<png_uint_32>(expect_height))) {
    png_destroy_read_struct(&png, &info, nullptr);
    *error = path + ": image is " + std::to_string(w) + "x" + std::to_string(h) + ", expected " +
             std::to_string(expect_width) + "x" + std::to_string(expect_height);
    return false;
  }
  if (png_get_bit_depth(png, info) == 16) png_set_strip_16(png);
  if (color == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (color == PNG_COLOR_TYPE_GRAY && png_get_bit_depth(png, info) < 8) {
    png_set_expand_gray_1_2_4_to_8(png);
  }
  if (color & PNG_COLOR_MASK_ALPHA) png_set_strip_alpha(png);
  if (color == PNG_COLOR_TYPE_RGB || color == PNG_COLOR_TYPE_RGB_ALPHA ||
      color == PNG_COLOR_TYPE_PALETTE) {
    png_set_rgb_to_gray_fixed(png, 1, 29900, 58700);  // BT.601: 0.299 R + 0.587 G
  }
  png_read_update_info(png, info);
  if (png_get_channels(png, info) != 1 || png_get_bit_depth(png, info) != 8) {
    png_destroy_read_struct(&png, &info, nullptr);
    *error = path + ": cannot convert to 8-bit gray";
    return false;
  }
  result->create(static_cast<int>(h), static_cast<int>(w), CV_8UC1);
  rows.resize(h);
  for (png_uint_32 y = 0; y < h; ++y) rows[y] = result->ptr<png_byte>(static_cast<int>(y));
  png_read_image(png, rows.data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return true;
}

bool write(const std::string& path, const cv::Mat& image, std::string* error, int compression) {
  if (image.empty() || image.depth() != CV_8U || (image.channels() != 1 && image.channels() != 3)) {
    *error = path + ": only 8-bit gray or BGR images can be written";
    return false;
  }
  std::unique_ptr<FILE, FileCloser> f(std::fopen(path.c_str(), "wb"));
  if (!f) {
    *error = path + ": cannot open for writing";
    return false;
  }
  std::string msg;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &msg, on_error, on_warning);
  png_infop info = png ? png_create_info_struct(png) : nullptr;
  std::vector<png_bytep> rows(static_cast<size_t>(image.rows));
  if (!png || !info || setjmp(png_jmpbuf(png))) {
    if (png) png_destroy_write_struct(&png, info ? &info : nullptr);
    *error = path + ": PNG write failed (" + (msg.empty() ? "libpng error" : msg) + ")";
    return false;
  }
  png_init_io(png, f.get());
  png_set_compression_level(png, compression);
  png_set_IHDR(png, info, static_cast<png_uint_32>(image.cols),
               static_cast<png_uint_32>(image.rows), 8,
               image.channels() == 1 ? PNG_COLOR_TYPE_GRAY : PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  if (image.channels() == 3) png_set_bgr(png);
  for (int y = 0; y < image.rows; ++y) {
    rows[static_cast<size_t>(y)] = const_cast<png_bytep>(image.ptr<png_byte>(y));
  }
  png_write_image(png, rows.data());
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  if (std::fflush(f.get()) != 0) {
    *error = path + ": write failed";
    return false;
  }
  return true;
}

}  // namespace agv::png
