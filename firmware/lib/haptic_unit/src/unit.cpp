#include "unit.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

namespace haptic {

const char* role_name(Role role) { return role == Role::dial ? "dial" : "drive"; }

Unit::Unit(Role role, Hardware hardware, Limits limits, const char* version)
    : role_(role), hw_(hardware), limits_(limits), version_(version) {}

std::size_t Unit::receive(char c, char* reply, std::size_t cap) {
  if (c == '\r') return 0;
  if (c != '\n') {
    if (length_ < kMaxLine) {
      line_[length_++] = c;
    } else {
      overflow_ = true;  // keep reading to the newline, then refuse the whole line
    }
    return 0;
  }
  line_[length_] = '\0';
  const bool overflow = overflow_;
  const std::size_t length = length_;
  length_ = 0;
  overflow_ = false;
  if (overflow) return refuse("line too long", nullptr, reply, cap);
  if (length == 0) return 0;  // a stray newline (a terminal's enter key) is no line
  if (fault_ != nullptr) return refuse("fault", fault_, reply, cap);
  return handle(line_, reply, cap);
}

std::size_t Unit::handle(char* line, char* reply, std::size_t cap) {
  const LineError error = unframe(line);
  if (error != LineError::none) {
    return refuse(describe(error), error == LineError::non_ascii ? nullptr : line, reply, cap);
  }
  // a valid line: the host is talking
  heard_ = true;
  last_heard_ms_ = hw_.clock.millis();
  if (std::strcmp(line, "HELLO") == 0) {
    char payload[kMaxLine];
    std::snprintf(payload, sizeof payload, "OK %s %s", role_name(role_), version_);
    return frame(payload, reply, cap);
  }
  if (std::strcmp(line, "Q") == 0) return state(reply, cap);
  if (std::strcmp(line, "STOP") == 0) {
    command_ = 0.0f;
    update();
    return frame("OK STOP", reply, cap);
  }
  return command_line(line, reply, cap);
}

std::size_t Unit::command_line(char* payload, char* reply, std::size_t cap) {
  const char verb = payload[0];
  if ((verb != 'I' && verb != 'W') || payload[1] != ' ') {
    return refuse("unknown command", payload, reply, cap);
  }
  if ((verb == 'I') != (role_ == Role::dial)) {
    return refuse(verb == 'I' ? "I is a dial's command; this unit is a drive"
                              : "W is a drive's command; this unit is a dial",
                  nullptr, reply, cap);
  }
  const char* number = payload + 2;
  char* end = nullptr;
  const float value = std::strtof(number, &end);
  if (end == number || *end != '\0' || !std::isfinite(value)) {
    return refuse(verb == 'I' ? "bad current" : "bad speed", number, reply, cap);
  }
  if (verb == 'I') {
    const float current_a = value / 1000.0f;  // mA -> A
    const float limit = limits_.max_current_a;
    command_ = current_a > limit ? limit : (current_a < -limit ? -limit : current_a);
  } else {
    const float limit = limits_.max_speed_rad_s;
    command_ = value > limit ? limit : (value < -limit ? -limit : value);
  }
  update();
  return state(reply, cap);
}

std::size_t Unit::state(char* reply, std::size_t cap) {
  const bool dial = role_ == Role::dial;
  const float joystick = dial ? hw_.joystick.axis() : 0.0f;
  const int button = dial && hw_.joystick.pressed() ? 1 : 0;
  char payload[kMaxReply];
  std::snprintf(payload, sizeof payload, "S %lu %.6f %.5f %.4f %.4f %d",
                static_cast<unsigned long>(hw_.clock.millis()),
                static_cast<double>(hw_.encoder.angle_rad()),
                static_cast<double>(hw_.encoder.speed_rad_s()),
                static_cast<double>(hw_.current.current_q_a() * 1000.0f),  // A -> mA
                static_cast<double>(joystick), button);
  return frame(payload, reply, cap);
}

std::size_t Unit::refuse(const char* message, const char* detail, char* reply, std::size_t cap) {
  ++refused_;
  char payload[kMaxReply];
  if (detail != nullptr) {
    std::snprintf(payload, sizeof payload, "E %s: '%.40s'", message, detail);
  } else {
    std::snprintf(payload, sizeof payload, "E %s", message);
  }
  return frame(payload, reply, cap);
}

bool Unit::watchdog_tripped() {
  return heard_ && hw_.clock.millis() - last_heard_ms_ > limits_.watchdog_ms;
}

float Unit::command() const { return command_; }

void Unit::update() {
  if (watchdog_tripped() || fault_ != nullptr) command_ = 0.0f;
  if (role_ == Role::dial) {
    hw_.motor.set_current_q(command_);
  } else {
    hw_.motor.set_speed(command_);
  }
}

}  // namespace haptic
