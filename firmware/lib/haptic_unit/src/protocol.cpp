#include "protocol.h"

#include <cstdio>
#include <cstring>

namespace haptic {

uint8_t checksum(const char* payload, std::size_t n) {
  uint8_t value = 0;
  for (std::size_t i = 0; i < n; ++i) value ^= static_cast<uint8_t>(payload[i]);
  return value;
}

std::size_t frame(const char* payload, char* out, std::size_t cap) {
  const std::size_t n = std::strlen(payload);
  if (n + 5 > cap) return 0;  // "*HH\n" and the NUL
  const int written =
      std::snprintf(out, cap, "%s*%02X\n", payload, static_cast<unsigned>(checksum(payload, n)));
  return written < 0 ? 0 : static_cast<std::size_t>(written);
}

static int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

LineError unframe(char* line) {
  const std::size_t n = std::strlen(line);
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned char c = static_cast<unsigned char>(line[i]);
    if (c < 0x20 || c > 0x7E) return LineError::non_ascii;
  }
  if (n < 3 || line[n - 3] != '*') return LineError::no_checksum;
  const int hi = hex_digit(line[n - 2]);
  const int lo = hex_digit(line[n - 1]);
  if (hi < 0 || lo < 0) return LineError::no_checksum;
  if (checksum(line, n - 3) != static_cast<uint8_t>(hi * 16 + lo)) return LineError::bad_checksum;
  line[n - 3] = '\0';
  return LineError::none;
}

const char* describe(LineError error) {
  switch (error) {
    case LineError::none:
      return "ok";
    case LineError::no_checksum:
      return "line without a checksum *HH";
    case LineError::bad_checksum:
      return "checksum mismatch";
    case LineError::non_ascii:
      return "non-ASCII byte in the line";
  }
  return "bad line";
}

}  // namespace haptic
