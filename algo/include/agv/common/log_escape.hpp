// Bytes from the network (an MQTT payload's ids, an HTTP request's fields) on their way into a log
// line: a newline would forge a journal entry and an ANSI escape sequence would rewrite the
// operator's terminal, so nothing but printable text leaves this function as it came.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace agv {

// Printable ASCII and well-formed UTF-8 (no overlong forms, no surrogates, no C1 controls) are
// kept; a backslash becomes "\\"; every other byte (control characters, DEL, bytes of malformed
// UTF-8) becomes "\xNN". At most max_bytes of the input are escaped; a longer input ends in
// "..." (a flood of long ids must not flood the journal).
std::string escape_for_log(std::string_view bytes, std::size_t max_bytes = 256);

// The length of the well-formed UTF-8 sequence at s[0] (1..4), 0 when the bytes there are not
// one (truncated, overlong, a surrogate, beyond U+10FFFF, a stray continuation byte).
std::size_t utf8_sequence_length(std::string_view s);

// True when every byte of s belongs to a well-formed UTF-8 sequence.
bool is_valid_utf8(std::string_view s);

}  // namespace agv
