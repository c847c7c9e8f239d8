// The hardware a unit's control code needs, as five small interfaces.
//
// The protocol and control code (unit.h) calls only these; the ESP32 build implements
// them with SimpleFOC (src/main.cpp: BLDCMotor, BLDCDriver3PWM, InlineCurrentSense,
// MagneticSensorI2C), the host build with a simulated motor (host/sim_hardware.h), so
// the same source runs on both.
#pragma once

#include <cstdint>

namespace haptic {

// The motor under field-oriented control: a q-current target (the dial renders a
// torque) or a shaft speed target (the drive's speed loop).
class Motor {
 public:
  virtual ~Motor() = default;
  // q-axis current target, A.
  virtual void set_current_q(float current_a) = 0;
  // shaft speed target, rad/s.
  virtual void set_speed(float speed_rad_s) = 0;
};

// The shaft encoder.
class Encoder {
 public:
  virtual ~Encoder() = default;
  // Unwrapped shaft angle (full turns counted), rad.
  virtual float angle_rad() = 0;
  // Filtered shaft speed, rad/s.
  virtual float speed_rad_s() = 0;
};

// The current sense, transformed to the rotor frame.
class CurrentSense {
 public:
  virtual ~CurrentSense() = default;
  // Measured q-axis current, A.
  virtual float current_q_a() = 0;
};

// The rotation joystick (on the dial unit; a drive has none) and its push button (the
// thumbstick's switch, or a momentary button beside the dial): the participant presses it
// when the guidewire's tip has reached the target.
class Joystick {
 public:
  virtual ~Joystick() = default;
  // The axis in [-1, 1].
  virtual float axis() = 0;
  // True while the button is held down (debounced).
  virtual bool pressed() = 0;
};

// The unit's clock.
class Clock {
 public:
  virtual ~Clock() = default;
  // Milliseconds since the unit started.
  virtual uint32_t millis() = 0;
};

// What a unit is built on: one of each.
struct Hardware {
  Motor& motor;
  Encoder& encoder;
  CurrentSense& current;
  Joystick& joystick;
  Clock& clock;
};

}  // namespace haptic
