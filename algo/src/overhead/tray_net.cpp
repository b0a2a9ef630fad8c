// The learned tray detector run with OpenCV's dnn module (ONNX). Where the build's OpenCV has no
// dnn module the detector refuses to load, by name, and the tracker runs without it.
#include "agv/overhead/tray_net.hpp"

#include <cmath>
#include <opencv2/imgproc.hpp>

#ifdef AGV_HAVE_OPENCV_DNN
#include <opencv2/dnn.hpp>
#endif

namespace agv::overhead {

#ifdef AGV_HAVE_OPENCV_DNN
struct TrayNet::Impl {
  mutable cv::dnn::Net net;
};
#else
struct TrayNet::Impl {};
#endif

TrayNet::TrayNet() = default;
TrayNet::~TrayNet() = default;
TrayNet::TrayNet(TrayNet&&) noexcept = default;
TrayNet& TrayNet::operator=(TrayNet&&) noexcept = default;

bool TrayNet::load(const char* data, std::size_t size, std::string* error,
                   const TrayNetGeometry& geometry) {
  impl_.reset();
  auto fail = [&](const std::string& s) {
    if (error) *error = "tray model: " + s;
    return false;
  };
  const int n = geometry.input_px;
  if (n < 16 || geometry.stride_px <= 0 || n % geometry.stride_px != 0 ||
      !(geometry.mm_per_px > 0.0)) {
    return fail("bad geometry (input a multiple of the stride)");
  }
  std::array<long long, 4> shape{};
  std::string why;
  if (!onnx_input_shape(data, size, &shape, &why)) return fail(why);
  if (shape[1] != 1 || shape[2] != n || shape[3] != n) {
    return fail("input is " + std::to_string(shape[0]) + " x " + std::to_string(shape[1]) + " x " +
                std::to_string(shape[2]) + " x " + std::to_string(shape[3]) +
                ", expected 1 x 1 x " + std::to_string(n) + " x " + std::to_string(n) +
                " (a model for another window)");
  }
#ifdef AGV_HAVE_OPENCV_DNN
  auto impl = std::make_unique<Impl>();
  try {
    impl->net = cv::dnn::readNetFromONNX(data, size);
    if (impl->net.empty()) return fail("OpenCV read no network from it");
    impl->net.setPreferableBackend(cv::dnn::DNN_BACKEND_OPENCV);
    impl->net.setPreferableTarget(cv::dnn::DNN_TARGET_CPU);
    const int dims[4] = {1, 1, n, n};
    impl->net.setInput(cv::Mat(4, dims, CV_32F, cv::Scalar(0)));
    const cv::Mat out = impl->net.forward();
    const int cells = n / geometry.stride_px;
    if (out.dims != 4 || out.size[1] != TrayNetGeometry::kChannels || out.size[2] != cells ||
        out.size[3] != cells) {
      return fail("output is not " + std::to_string(TrayNetGeometry::kChannels) + " x " +
                  std::to_string(cells) + " x " + std::to_string(cells));
    }
  } catch (const cv::Exception& e) {
    return fail(std::string("OpenCV could not read it: ") + e.what());
  }
  impl_ = std::move(impl);
  geometry_ = geometry;
  return true;
#else
  return fail("this build's OpenCV has no dnn module; the learned detector is not available");
#endif
}

std::vector<OrientedBox> TrayNet::detect(const cv::Mat& window, const TrayNetParams& p) const {
  const int n = geometry_.input_px;
  if (!impl_ || window.type() != CV_8UC1 || window.rows != n || window.cols != n) return {};
#ifdef AGV_HAVE_OPENCV_DNN
  // The network sees the window standardised (lighting and gain drop out).
  cv::Scalar mean, sd;
  cv::meanStdDev(window, mean, sd);
  cv::Mat f;
  window.convertTo(f, CV_32F, 1.0 / std::max(sd[0], 8.0), -mean[0] / std::max(sd[0], 8.0));
  const int dims[4] = {1, 1, n, n};
  const cv::Mat blob(4, dims, CV_32F, f.data);
  cv::Mat out;
  try {
    impl_->net.setInput(blob);
    out = impl_->net.forward();
  } catch (const cv::Exception&) {
    return {};
  }
  std::vector<OrientedBox> boxes;
  if (out.dims != 4 || !decode_tray_output(out.ptr<float>(), out.size[1], out.size[2], out.size[3],
                                           geometry_.stride_px, p.min_score, &boxes)) {
    return {};
  }
  return p.fuse_boxes ? nms_fused(std::move(boxes), p.nms_iou)
                      : nms_oriented(std::move(boxes), p.nms_iou);
#else
  (void)p;
  return {};
#endif
}

std::vector<PlaneTray> TrayNet::detect_on_plane(const cv::Mat& gray, const site::CeilingCamera& cam,
                                                Vec2 centre_mm, double plane_mm,
                                                const TrayNetParams& p) const {
  RectifiedWindow w;
  if (!impl_ || !rectify_window(gray, cam, centre_mm, plane_mm, geometry_.input_px,
                                geometry_.mm_per_px, &w)) {
    return {};
  }
  std::vector<PlaneTray> out;
  for (const OrientedBox& b : detect(w.gray, p)) {
    PlaneTray t;
    t.centre_mm = window_to_plane(w, b.cx, b.cy);
    // Window y runs against site y: the angle turns sign.
    double a = -b.angle_rad;
    if (a < 0.0) a += kPi;
    t.axis_rad = a >= kPi ? a - kPi : a;
    t.length_mm = b.length * w.mm_per_px;
    t.width_mm = b.width * w.mm_per_px;
    t.score = b.score;
    out.push_back(t);
  }
  return out;
}

}  // namespace agv::overhead
