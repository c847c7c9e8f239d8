// The protocol and the watchdog (lib/haptic_unit) on a fake hardware with a hand-set
// clock. Expected lines are worked out by hand: the checksum is the XOR of the
// payload's bytes, as teleop_core/loop/hardware.py computes it.
#include <cstring>
#include <string>
#include <vector>

#include "runner.h"
#include "unit.h"

namespace {

struct FakeHardware : haptic::Motor, haptic::Encoder, haptic::CurrentSense, haptic::Joystick,
                      haptic::Clock {
  float current_a = -1.0f, speed_cmd = -1.0f;
  float angle = 0.5f, speed = 1.25f, iq = 0.002f, joystick = -0.5f;
  bool button = false;
  uint32_t now_ms = 120;
  void set_current_q(float a) override { current_a = a; }
  void set_speed(float w) override { speed_cmd = w; }
  float angle_rad() override { return angle; }
  float speed_rad_s() override { return speed; }
  float current_q_a() override { return iq; }
  float axis() override { return joystick; }
  bool pressed() override { return button; }
  uint32_t millis() override { return now_ms; }
  haptic::Hardware hardware() { return haptic::Hardware{*this, *this, *this, *this, *this}; }
};

// Sends `payload` framed (or `raw` as is) and returns the reply without its newline.
std::string send_raw(haptic::Unit& unit, const std::string& raw) {
  char reply[haptic::kMaxReply] = {};
  std::size_t n = 0;
  for (char c : raw) n = unit.receive(c, reply, sizeof reply);
  std::string text(reply, n);
  if (!text.empty() && text.back() == '\n') text.pop_back();
  return text;
}

std::string send(haptic::Unit& unit, const std::string& payload) {
  char line[haptic::kMaxReply];
  haptic::frame(payload.c_str(), line, sizeof line);
  return send_raw(unit, line);
}

// The payload of a framed reply, checked.
std::string payload_of(const std::string& reply) {
  std::string copy = reply;
  std::vector<char> buffer(copy.begin(), copy.end());
  buffer.push_back('\0');
  if (haptic::unframe(buffer.data()) != haptic::LineError::none) return "<bad frame>";
  return buffer.data();
}

}  // namespace

TEST(checksum_is_the_xor_of_the_payload) {
  // 'Q' = 0x51; "I 1" = 0x49 ^ 0x20 ^ 0x31 = 0x58 (as the host's test)
  CHECK(haptic::checksum("Q", 1) == 0x51);
  char out[16];
  CHECK(haptic::frame("I 1", out, sizeof out) == 7);
  CHECK(std::strcmp(out, "I 1*58\n") == 0);
  CHECK(haptic::frame("I 1", out, 7) == 0);  // 7 characters and the NUL do not fit in 7
}

TEST(unframe_refuses_corrupt_lines) {
  char good[] = "I 1*58";
  CHECK(haptic::unframe(good) == haptic::LineError::none);
  CHECK(std::strcmp(good, "I 1") == 0);
  char lower[] = "I 2*5b";  // 0x49 ^ 0x20 ^ 0x32 = 0x5B; lower-case hex is accepted
  CHECK(haptic::unframe(lower) == haptic::LineError::none);
  char bad[] = "I 1*59";
  CHECK(haptic::unframe(bad) == haptic::LineError::bad_checksum);
  char none[] = "I 1";
  CHECK(haptic::unframe(none) == haptic::LineError::no_checksum);
  char not_hex[] = "I 1*5G";
  CHECK(haptic::unframe(not_hex) == haptic::LineError::no_checksum);
  char binary[] = "I \xff*00";
  CHECK(haptic::unframe(binary) == haptic::LineError::non_ascii);
}

TEST(hello_names_role_and_version) {
  FakeHardware hw;
  haptic::Unit dial(haptic::Role::dial, hw.hardware(), {}, "1.0.0");
  CHECK(payload_of(send(dial, "HELLO")) == "OK dial 1.0.0");
  haptic::Unit drive(haptic::Role::drive, hw.hardware(), {}, "1.0.0");
  CHECK(payload_of(send(drive, "HELLO")) == "OK drive 1.0.0");
}

TEST(a_current_command_reaches_the_motor_and_the_state_comes_back) {
  FakeHardware hw;
  haptic::Unit unit(haptic::Role::dial, hw.hardware());
  const std::string reply = send(unit, "I 12.5");
  // clock 120 ms, angle 0.5 rad, speed 1.25 rad/s, iq 0.002 A = 2 mA, joystick -0.5,
  // button up
  CHECK(payload_of(reply) == "S 120 0.500000 1.25000 2.0000 -0.5000 0");
  CHECK_NEAR(hw.current_a, 0.0125f, 1e-7f);  // mA -> A
  CHECK(payload_of(send(unit, "Q")) == "S 120 0.500000 1.25000 2.0000 -0.5000 0");
}

TEST(the_state_line_ends_with_the_button_while_it_is_held) {
  FakeHardware hw;
  haptic::Unit unit(haptic::Role::dial, hw.hardware());
  hw.button = true;
  // "S 120 0.500000 1.25000 2.0000 -0.5000 1": its bytes XOR to 0x48
  CHECK(send(unit, "Q") == "S 120 0.500000 1.25000 2.0000 -0.5000 1*48");
  hw.button = false;
  CHECK(payload_of(send(unit, "Q")) == "S 120 0.500000 1.25000 2.0000 -0.5000 0");
}

TEST(a_drive_takes_speed_and_reports_no_joystick) {
  FakeHardware hw;
  hw.button = true;  // a drive has neither: both fields 0
  haptic::Unit unit(haptic::Role::drive, hw.hardware());
  CHECK(payload_of(send(unit, "W -3.5")) == "S 120 0.500000 1.25000 2.0000 0.0000 0");
  CHECK_NEAR(hw.speed_cmd, -3.5f, 1e-7f);
}

TEST(each_role_refuses_the_other_roles_command) {
  FakeHardware hw;
  haptic::Unit dial(haptic::Role::dial, hw.hardware());
  CHECK(payload_of(send(dial, "W 1")) == "E W is a drive's command; this unit is a dial");
  haptic::Unit drive(haptic::Role::drive, hw.hardware());
  CHECK(payload_of(send(drive, "I 1")) == "E I is a dial's command; this unit is a drive");
  CHECK(hw.current_a == -1.0f);  // never set
  CHECK(dial.lines_refused() == 1 && drive.lines_refused() == 1);
}

TEST(malformed_lines_get_an_e_and_change_nothing) {
  FakeHardware hw;
  haptic::Unit unit(haptic::Role::dial, hw.hardware());
  send(unit, "I 2");
  CHECK_NEAR(unit.command(), 0.002f, 1e-7f);
  CHECK(payload_of(send(unit, "I abc")) == "E bad current: 'abc'");
  CHECK(payload_of(send(unit, "I 1.5x")) == "E bad current: '1.5x'");
  CHECK(payload_of(send(unit, "I nan")) == "E bad current: 'nan'");
  CHECK(payload_of(send(unit, "I inf")) == "E bad current: 'inf'");
  CHECK(payload_of(send(unit, "I")) == "E unknown command: 'I'");
  CHECK(payload_of(send(unit, "X 1")) == "E unknown command: 'X 1'");
  CHECK(payload_of(send_raw(unit, "I 1*59\n")) == "E checksum mismatch: 'I 1*59'");
  CHECK(payload_of(send_raw(unit, "I 1\n")) == "E line without a checksum *HH: 'I 1'");
  CHECK(payload_of(send_raw(unit, "I \x01*00\n")) == "E non-ASCII byte in the line");
  CHECK_NEAR(unit.command(), 0.002f, 1e-7f);
  CHECK(unit.lines_refused() == 9);
}

TEST(an_overlong_line_is_refused_whole_and_the_next_one_is_read) {
  FakeHardware hw;
  haptic::Unit unit(haptic::Role::dial, hw.hardware());
  CHECK(payload_of(send_raw(unit, std::string(200, '7') + "\n")) == "E line too long");
  CHECK(payload_of(send(unit, "HELLO")).rfind("OK dial ", 0) == 0);
}

TEST(crlf_and_stray_newlines_are_accepted) {
  FakeHardware hw;
  haptic::Unit unit(haptic::Role::dial, hw.hardware());
  CHECK(send_raw(unit, "\n").empty());
  CHECK(payload_of(send_raw(unit, "Q*51\r\n")).rfind("S 120 ", 0) == 0);
}

TEST(commands_beyond_the_limits_are_clamped) {
  FakeHardware hw;
  haptic::Limits limits;
  limits.max_current_a = 0.5f;
  limits.max_speed_rad_s = 20.0f;
  haptic::Unit dial(haptic::Role::dial, hw.hardware(), limits);
  send(dial, "I 9000");
  CHECK_NEAR(hw.current_a, 0.5f, 1e-7f);
  send(dial, "I -9000");
  CHECK_NEAR(hw.current_a, -0.5f, 1e-7f);
  haptic::Unit drive(haptic::Role::drive, hw.hardware(), limits);
  send(drive, "W 100");
  CHECK_NEAR(hw.speed_cmd, 20.0f, 1e-7f);
}

TEST(stop_zeroes_the_command) {
  FakeHardware hw;
  haptic::Unit unit(haptic::Role::dial, hw.hardware());
  send(unit, "I 3");
  CHECK(payload_of(send(unit, "STOP")) == "OK STOP");
  CHECK(unit.command() == 0.0f);
  CHECK(hw.current_a == 0.0f);
}

TEST(the_watchdog_zeroes_the_command_when_the_host_goes_quiet) {
  FakeHardware hw;
  haptic::Limits limits;
  limits.watchdog_ms = 100;
  haptic::Unit unit(haptic::Role::dial, hw.hardware(), limits);
  unit.update();
  CHECK(!unit.watchdog_tripped());  // nothing heard yet: nothing to zero
  send(unit, "I 4");
  hw.now_ms += 100;
  unit.update();
  CHECK(!unit.watchdog_tripped());
  CHECK_NEAR(hw.current_a, 0.004f, 1e-7f);
  hw.now_ms += 1;  // 101 ms of silence
  unit.update();
  CHECK(unit.watchdog_tripped());
  CHECK(hw.current_a == 0.0f);
  CHECK(unit.command() == 0.0f);
  // the host back: a query does not bring the old command back
  send(unit, "Q");
  CHECK(!unit.watchdog_tripped());
  unit.update();
  CHECK(hw.current_a == 0.0f);
}

TEST(the_watchdog_survives_the_clock_wrapping) {
  FakeHardware hw;
  hw.now_ms = 0xFFFFFFF0u;
  haptic::Unit unit(haptic::Role::drive, hw.hardware());
  send(unit, "W 2");
  hw.now_ms = 0x00000010u;  // 32 ms later, through the wrap
  unit.update();
  CHECK(!unit.watchdog_tripped());
  CHECK_NEAR(hw.speed_cmd, 2.0f, 1e-7f);
}

TEST(a_faulted_unit_refuses_every_line_and_commands_nothing) {
  FakeHardware hw;
  haptic::Unit unit(haptic::Role::dial, hw.hardware());
  unit.set_fault("FOC alignment failed");
  CHECK(payload_of(send(unit, "HELLO")) == "E fault: 'FOC alignment failed'");
  CHECK(payload_of(send(unit, "I 3")) == "E fault: 'FOC alignment failed'");
  unit.update();
  CHECK(hw.current_a == 0.0f);
}
