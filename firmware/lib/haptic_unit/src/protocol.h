// The line framing of the host's serial protocol, version 1.
//
// Every line is `<payload>*<HH>\n`, HH the XOR of the payload's bytes in two upper-case
// hex digits (as NMEA 0183 does). The host side is teleop_core/loop/hardware.py; the two
// must agree byte for byte.
#pragma once

#include <cstddef>
#include <cstdint>

namespace haptic {

// Longest line a unit accepts, payload and checksum, without the newline.
constexpr std::size_t kMaxLine = 64;

// The XOR of `n` bytes of `payload`.
uint8_t checksum(const char* payload, std::size_t n);

// Writes `<payload>*HH\n` into `out` (NUL-terminated); returns its length, or 0 when it
// does not fit in `cap` bytes.
std::size_t frame(const char* payload, char* out, std::size_t cap);

enum class LineError : uint8_t {
  none,
  no_checksum,   // no `*HH` at the end
  bad_checksum,  // HH differs from the payload's XOR
  non_ascii,     // a byte outside printable ASCII
};

// Checks a received line (no newline, NUL-terminated, written in place): on success
// cuts it at the `*`, so `line` is the payload.
LineError unframe(char* line);

// A short description of `error` for an `E` line.
const char* describe(LineError error);

}  // namespace haptic
