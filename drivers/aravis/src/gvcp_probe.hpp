// Asks a GigE Vision camera for one bootstrap register over a socket of our own, to learn quickly
// whether a silent camera is still there. GigE Vision devices answer register reads from any
// application, not only from the one that controls them, so this does not disturb the stream.
#pragma once

#include <cstdint>
#include <string>

namespace agv::aravis {

class GvcpProbe {
 public:
  enum class Result {
    kNothing,   // no answer yet
    kAnswered,  // the camera answered a request
    kRefused,   // the host reports that nothing listens at the camera's address and port
  };

  GvcpProbe() = default;
  ~GvcpProbe();
  GvcpProbe(const GvcpProbe&) = delete;
  GvcpProbe& operator=(const GvcpProbe&) = delete;

  // IPv4 address in dotted form; false with *error.
  bool open(const std::string& ipv4, std::uint16_t port, std::string* error);
  void close();
  bool is_open() const { return fd_ >= 0; }
  // Sends one request, then reads what has arrived (never waits).
  Result send_request();
  Result poll_answers();

 private:
  int fd_ = -1;
  std::uint16_t request_id_ = 0;
};

}  // namespace agv::aravis
