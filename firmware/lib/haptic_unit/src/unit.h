// A motor unit's protocol and control, apart from the hardware calls.
//
// `Unit` assembles the host's lines byte by byte, answers each (HELLO, I, W, Q, STOP;
// `E <message>` for a line it cannot accept), and applies the command to the motor at
// every control cycle (`update`). A watchdog zeroes the command when no valid line has
// come for `Limits::watchdog_ms`: a host that crashed or a cable pulled leaves the motor
// without torque (dial) or stopped (drive), never holding the last command.
#pragma once

#include <cstddef>
#include <cstdint>

#include "hardware.h"
#include "protocol.h"
#include "version.h"

namespace haptic {

enum class Role : uint8_t { dial, drive };

// "dial" or "drive", as the HELLO reply names the role.
const char* role_name(Role role);

struct Limits {
  // Largest q-current a dial accepts, A; larger commands are clamped to it.
  float max_current_a = 0.5f;
  // Largest shaft speed a drive accepts, rad/s (0.2 m/s of guidewire on a 10 mm wheel);
  // larger commands are clamped to it.
  float max_speed_rad_s = 20.0f;
  // The command is zeroed when no valid line has come for this long, ms (ten of the
  // host's 100 Hz updates).
  uint32_t watchdog_ms = 100;
};

// Longest reply, framed, with its NUL.
constexpr std::size_t kMaxReply = 2 * kMaxLine;

class Unit {
 public:
  Unit(Role role, Hardware hardware, Limits limits = Limits{},
       const char* version = HAPTIC_UNIT_VERSION);

  // One received byte. When it ends a line, the framed reply is written into `reply`
  // (at least kMaxReply bytes) and its length returned; otherwise 0.
  std::size_t receive(char c, char* reply, std::size_t cap);

  // The control cycle: the command (or 0, once the watchdog has tripped) to the motor.
  void update();

  Role role() const { return role_; }
  // The command in force: A on a dial, rad/s on a drive.
  float command() const;
  // True while the host has been silent for longer than the watchdog allows.
  bool watchdog_tripped();
  // Lines answered with `E`.
  uint32_t lines_refused() const { return refused_; }
  // A fault found at start-up (the motor or encoder did not initialise): every line is
  // then answered `E fault: <message>` and the motor gets no command. The message must
  // outlive the unit.
  void set_fault(const char* message) { fault_ = message; }

 private:
  std::size_t handle(char* line, char* reply, std::size_t cap);
  std::size_t command_line(char* payload, char* reply, std::size_t cap);
  std::size_t state(char* reply, std::size_t cap);
  std::size_t refuse(const char* message, const char* detail, char* reply, std::size_t cap);

  Role role_;
  Hardware hw_;
  Limits limits_;
  const char* version_;
  char line_[kMaxLine + 1] = {};
  std::size_t length_ = 0;
  bool overflow_ = false;
  float command_ = 0.0f;
  bool heard_ = false;
  uint32_t last_heard_ms_ = 0;
  uint32_t refused_ = 0;
  const char* fault_ = nullptr;
};

}  // namespace haptic
