// The ESP32 build: the unit's hardware calls on SimpleFOC.
//
// One ESP32 per motor: a 2804 gimbal PMSM (7 pole pairs) on a DRV8313 three-phase driver
// (BLDCDriver3PWM), two INA240A2 inline current-sense amplifiers on phases A and B
// (InlineCurrentSense), an AS5600 magnetic encoder on I2C (MagneticSensorI2C), and on
// the dial unit the rotation joystick's axis on an ADC pin and its push button (the
// participant's "reached") on a digital pin. SimpleFOC runs the
// field-oriented current loop (TorqueControlType::foc_current); the dial commands a
// q-current (MotionControlType::torque), the drive a shaft speed through SimpleFOC's
// velocity loop (MotionControlType::velocity). The protocol and the watchdog are
// lib/haptic_unit's, the same code the host build tests.
//
// Build one role: `pio run -e dial` or `pio run -e drive` (the environment defines
// HAPTIC_UNIT_ROLE_DIAL or HAPTIC_UNIT_ROLE_DRIVE). The wiring is in the hardware
// tutorial (docs/tutorials/hardware.md); the pins below must match it.
#include <Arduino.h>
#include <SimpleFOC.h>
#include <Wire.h>

#include "unit.h"

#if defined(HAPTIC_UNIT_ROLE_DIAL)
constexpr haptic::Role kRole = haptic::Role::dial;
#elif defined(HAPTIC_UNIT_ROLE_DRIVE)
constexpr haptic::Role kRole = haptic::Role::drive;
#else
#error "build with -DHAPTIC_UNIT_ROLE_DIAL or -DHAPTIC_UNIT_ROLE_DRIVE (pio run -e dial / -e drive)"
#endif

// Pins (ESP32 DevKit v1)
constexpr int kPinPwmA = 25;      // DRV8313 IN1
constexpr int kPinPwmB = 26;      // DRV8313 IN2
constexpr int kPinPwmC = 27;      // DRV8313 IN3
constexpr int kPinEnable = 14;    // DRV8313 EN1-EN3 (tied)
constexpr int kPinSenseA = 34;    // INA240 on phase A, output (ADC1, input only)
constexpr int kPinSenseB = 35;    // INA240 on phase B, output (ADC1, input only)
constexpr int kPinSda = 21;       // AS5600 SDA
constexpr int kPinScl = 22;       // AS5600 SCL
constexpr int kPinJoystick = 32;  // joystick axis wiper (ADC1), dial unit only
constexpr int kPinButton = 33;    // joystick's switch (SW) to GND, internal pull-up; dial only

// Motor and sensing
constexpr int kPolePairs = 7;              // 2804 gimbal motor
constexpr float kSupplyV = 12.0f;          // DRV8313 VM
constexpr float kVoltageLimitV = 6.0f;     // half the supply: the gimbal motor's ~10 ohm phases
constexpr float kShuntOhm = 0.01f;         // 10 mOhm phase shunt
constexpr float kSenseGainVPerV = 50.0f;   // INA240A2: 50 V/V, so 0.5 V per A
constexpr float kCurrentLimitA = 0.7f;     // the drive's continuous current
constexpr float kVelocityLimitRadS = 20.0f;
constexpr float kJoystickDeadband = 0.05f;
constexpr uint32_t kButtonDebounceMs = 20;  // a contact's bounce settles within this
constexpr uint32_t kI2cHz = 400000;

BLDCMotor motor(kPolePairs);
BLDCDriver3PWM driver(kPinPwmA, kPinPwmB, kPinPwmC, kPinEnable);
InlineCurrentSense current_sense(kShuntOhm, kSenseGainVPerV, kPinSenseA, kPinSenseB);
MagneticSensorI2C sensor(AS5600_I2C);

class FocMotor : public haptic::Motor {
 public:
  void set_current_q(float current_a) override { motor.target = current_a; }
  void set_speed(float speed_rad_s) override { motor.target = speed_rad_s; }
};

class FocEncoder : public haptic::Encoder {
 public:
  // getAngle() counts full turns; shaft_velocity is SimpleFOC's low-passed estimate
  float angle_rad() override { return sensor.getAngle(); }
  float speed_rad_s() override { return motor.shaft_velocity; }
};

class FocCurrent : public haptic::CurrentSense {
 public:
  // the q current loopFOC() measured and low-passed (LPF_current_q)
  float current_q_a() override { return motor.current.q; }
};

class AdcJoystick : public haptic::Joystick {
 public:
  void calibrate() {
    long sum = 0;
    for (int i = 0; i < 32; ++i) sum += analogRead(kPinJoystick);
    centre_ = sum / 32.0f;
  }
  float axis() override {
    if (kRole != haptic::Role::dial) return 0.0f;
    float value = (analogRead(kPinJoystick) - centre_) / 2048.0f;  // 12-bit ADC
    if (fabsf(value) < kJoystickDeadband) return 0.0f;
    return value > 1.0f ? 1.0f : (value < -1.0f ? -1.0f : value);
  }
  // The switch closes to GND (active low); a level counts once it has held for the
  // debounce time.
  bool pressed() override {
    if (kRole != haptic::Role::dial) return false;
    const bool level = digitalRead(kPinButton) == LOW;
    const uint32_t now = ::millis();
    if (level != raw_) {
      raw_ = level;
      since_ms_ = now;
    } else if (now - since_ms_ >= kButtonDebounceMs) {
      stable_ = level;
    }
    return stable_;
  }

 private:
  float centre_ = 2048.0f;
  bool raw_ = false, stable_ = false;
  uint32_t since_ms_ = 0;
};

class ArduinoClock : public haptic::Clock {
 public:
  uint32_t millis() override { return ::millis(); }
};

FocMotor foc_motor;
FocEncoder foc_encoder;
FocCurrent foc_current;
AdcJoystick joystick;
ArduinoClock arduino_clock;
haptic::Unit unit(kRole, haptic::Hardware{foc_motor, foc_encoder, foc_current, joystick,
                                          arduino_clock});
char reply[haptic::kMaxReply];

void setup() {
  Serial.begin(115200);
  Wire.begin(kPinSda, kPinScl, kI2cHz);
  sensor.init(&Wire);
  motor.linkSensor(&sensor);

  driver.voltage_power_supply = kSupplyV;
  driver.voltage_limit = kVoltageLimitV;
  if (!driver.init()) unit.set_fault("DRV8313 driver did not initialise");
  motor.linkDriver(&driver);
  current_sense.linkDriver(&driver);

  motor.voltage_limit = kVoltageLimitV;
  motor.current_limit = kCurrentLimitA;
  motor.velocity_limit = kVelocityLimitRadS;
  motor.torque_controller = TorqueControlType::foc_current;
  motor.controller =
      kRole == haptic::Role::dial ? MotionControlType::torque : MotionControlType::velocity;
  motor.LPF_velocity.Tf = 0.005f;  // the speed the state line reports
  if (kRole == haptic::Role::drive) {
    // speed loop: rad/s error -> q current, A
    motor.PID_velocity.P = 0.02f;
    motor.PID_velocity.I = 0.6f;
    motor.PID_velocity.D = 0.0f;
    motor.PID_velocity.limit = kCurrentLimitA;
  }
  motor.target = 0.0f;
  if (!motor.init()) unit.set_fault("motor did not initialise");
  if (!current_sense.init()) unit.set_fault("INA240 current sense did not initialise");
  motor.linkCurrentSense(&current_sense);
  if (!motor.initFOC()) unit.set_fault("FOC alignment failed (check the encoder and phases)");
  if (kRole == haptic::Role::dial) {
    pinMode(kPinJoystick, INPUT);
    pinMode(kPinButton, INPUT_PULLUP);
    joystick.calibrate();  // the joystick at rest at power-up is its centre
  }
}

void loop() {
  motor.loopFOC();
  motor.move();
  unit.update();
  while (Serial.available() > 0) {
    const std::size_t n = unit.receive(static_cast<char>(Serial.read()), reply, sizeof reply);
    if (n > 0) Serial.write(reinterpret_cast<const uint8_t*>(reply), n);
  }
}
