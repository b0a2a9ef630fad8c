// Image formation after scene radiance; see render_effects.hpp.
#include "render_effects.hpp"

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace agv::sim {

IlluminationGradient illumination_gradient(int width_px, int height_px, double direction_deg) {
  IlluminationGradient g;
  const double dir = deg_to_rad(direction_deg);
  g.dx = std::cos(dir);
  g.dy = std::sin(dir);
  double tmin = 1e300, tmax = -1e300;
  for (int cy = 0; cy <= 1; ++cy) {
    for (int cx = 0; cx <= 1; ++cx) {
      const double t = cx * (width_px - 1) * g.dx + cy * (height_px - 1) * g.dy;
      tmin = std::min(tmin, t);
      tmax = std::max(tmax, t);
    }
  }
  g.tmin = tmin;
  g.span = std::max(1e-9, tmax - tmin);
  return g;
}

// Illumination multiplies scene radiance, so it comes before the optical blurs.
void apply_illumination(const RenderOptions& o, cv::Mat* img) {
  const int w = img->cols, h = img->rows;
  const double gain = std::max(0.0, o.exposure_gain);
  if (o.illumination_ratio != 1.0 || gain != 1.0) {
    const IlluminationGradient g = illumination_gradient(w, h, o.illumination_direction_deg);
    const double ratio = std::clamp(o.illumination_ratio, 0.0, 10.0);
    for (int y = 0; y < h; ++y) {
      float* row = img->ptr<float>(y);
      for (int x = 0; x < w; ++x) {
        const double t = g.at(x, y);
        row[x] = static_cast<float>(static_cast<double>(row[x]) * gain * (1.0 + (ratio - 1.0) * t));
      }
    }
  }
}

void apply_motion_blur(const RenderOptions& o, const FloorProjector& camera, Vec2 centre_v,
                       bool centre_ok, cv::Mat* img) {
  if (o.exposure_s > 0.0 && (o.speed_mps != 0.0 || o.yaw_rate_radps != 0.0)) {
    // Image motion of the floor point under the image centre during the exposure. A fixed
    // world point moves in the vehicle frame with velocity (-v + w*y, -w*x).
    const Vec2 p = centre_v;
    const double t = o.exposure_s;
    const Vec2 d{t * (-o.speed_mps * 1000.0 + o.yaw_rate_radps * p.y),
                 t * (-o.yaw_rate_radps * p.x)};
    Vec2 pa, pb;
    if (centre_ok && camera.vehicle_to_pixel({p.x - 0.5 * d.x, p.y - 0.5 * d.y}, &pa) &&
        camera.vehicle_to_pixel({p.x + 0.5 * d.x, p.y + 0.5 * d.y}, &pb)) {
      const double mx = pb.x - pa.x, my = pb.y - pa.y, len = std::hypot(mx, my);
      if (len > 0.25 && len < 500.0) {
        const int half = static_cast<int>(std::ceil(0.5 * len)) + 1;
        cv::Mat k = cv::Mat::zeros(2 * half + 1, 2 * half + 1, CV_32FC1);
        const int steps = static_cast<int>(std::ceil(len * 8.0)) + 1;
        for (int s = 0; s < steps; ++s) {
          const double f = (s + 0.5) / steps - 0.5;
          const double kx = half + f * mx, ky = half + f * my;
          const int x0 = static_cast<int>(std::floor(kx)), y0 = static_cast<int>(std::floor(ky));
          const double ax = kx - x0, ay = ky - y0;
          k.at<float>(y0, x0) += static_cast<float>((1 - ax) * (1 - ay));
          k.at<float>(y0, x0 + 1) += static_cast<float>(ax * (1 - ay));
          k.at<float>(y0 + 1, x0) += static_cast<float>((1 - ax) * ay);
          k.at<float>(y0 + 1, x0 + 1) += static_cast<float>(ax * ay);
        }
        k /= cv::sum(k)[0];
        cv::filter2D(*img, *img, -1, k, cv::Point(-1, -1), 0.0, cv::BORDER_REFLECT);
      }
    }
  }
}

cv::Mat quantise_with_noise(const cv::Mat& img, double read_noise_sigma, double shot_noise_gain,
                            std::mt19937_64& rng) {
  const int w = img.cols, h = img.rows;
  cv::Mat out(h, w, CV_8UC1);
  const bool noisy = read_noise_sigma > 0.0 || shot_noise_gain > 0.0;
  std::normal_distribution<double> nd(0.0, 1.0);
  for (int y = 0; y < h; ++y) {
    const float* src = img.ptr<float>(y);
    auto* dst = out.ptr<std::uint8_t>(y);
    for (int x = 0; x < w; ++x) {
      double v = static_cast<double>(src[x]);
      if (noisy) {
        const double var =
            read_noise_sigma * read_noise_sigma + std::max(0.0, shot_noise_gain) * std::max(0.0, v);
        v += std::sqrt(var) * nd(rng);
      }
      dst[x] = static_cast<std::uint8_t>(std::clamp(std::lround(v), 0L, 255L));
    }
  }
  return out;
}

}  // namespace agv::sim
