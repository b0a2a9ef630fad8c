#include "agv/hal/camera.hpp"

namespace agv::hal {

const char* to_string(CameraStatus s) {
  switch (s) {
    case CameraStatus::kOk:
      return "ok";
    case CameraStatus::kTimeout:
      return "timeout";
    case CameraStatus::kEndOfStream:
      return "end of stream";
    case CameraStatus::kNotStarted:
      return "not started";
    case CameraStatus::kDisconnected:
      return "disconnected";
    case CameraStatus::kInvalidArgument:
      return "invalid argument";
    case CameraStatus::kDeviceError:
      return "device error";
  }
  return "unknown camera status";
}

}  // namespace agv::hal
