// Shared by the recording reader (recording.cpp) and writers (recording_write.cpp).
#pragma once

#include <string_view>

namespace agv::recording {

// A file name below the recording directory: relative, no "." or ".." component, no trailing
// "/", no control characters or '"'.
bool safe_relative_path(std::string_view f);

}  // namespace agv::recording
