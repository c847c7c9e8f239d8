// The host build's hardware: a simulated PMSM unit behind haptic::Hardware.
//
// It stands in for the ESP32's SimpleFOC objects when the firmware runs on the host:
// the shaft's dynamics integrated at 10 kHz, the FOC current loop as a first-order lag,
// the AS5600's 12-bit angle (4096 counts per turn, unwrapped), a speed estimate from the
// quantised angle low-passed as SimpleFOC's LPF_velocity does, and the INA240's noise
// on the measured q current. Parameters follow the study's models (teleop_core: the
// dial's DialParams, the follower's plant and sensors); where those are silent they are
// assumptions, marked below.
//
// A dial unit has a hand on it: a grip stiffness and damping about an aimed angle that
// follows a script (piecewise-linear in the time since the last HELLO, as a person who
// starts again at each trial), a joystick axis that follows another, and the joystick's
// button, pressed while a third is 0.5 or more. A drive unit
// pushes a guidewire through a friction wheel against a load that grows with the
// inserted length.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "hardware.h"
#include "unit.h"

namespace haptic {

// A piecewise-linear function of time, held constant past its ends.
class Profile {
 public:
  Profile() = default;
  // "t0:v0,t1:v1,..." (s:value) or a single value; false on a malformed text.
  bool parse(const std::string& text);
  double at(double t_s) const;

 private:
  std::vector<std::pair<double, double>> points_;
};

struct SimParams {
  Role role = Role::dial;
  // Torque constant of the 2804 gimbal motor, N m/A (the drive's; the dial renders its
  // current through the calibrated characteristic below).
  double torque_constant_n_m_per_a = 0.043;
  int pole_pairs = 7;
  int encoder_counts = 4096;  // AS5600, 12 bits
  double inertia_kg_m2 = 6.0e-6;
  double viscous_n_m_s_per_rad = 1.0e-5;
  double coulomb_n_m = 3.0e-4;
  // Closed current loop as a first-order lag, s.
  double current_time_constant_s = 1.0e-3;
  // INA240 noise on the measured q current, A (standard deviation).
  double current_noise_a = 5.0e-4;
  // SimpleFOC's LPF_velocity time constant, s.
  double velocity_filter_s = 5.0e-3;
  // Dial: eq. 14's loading polynomial F(i) = a i^2 + b i + c (i in mA, F in N) on the
  // calibration lever, the characteristic the host's Psi map inverts.
  double poly_a = -0.023155, poly_b = 0.725796, poly_c = -0.019272;
  double lever_arm_m = 0.025;
  // Dial: the hand's grip (teleop_core.loop.drivers' finger grip).
  double grip_n_m_per_rad = 0.3;
  double grip_damping_n_m_s_per_rad = 3.0e-3;
  Profile hand_aim_rad;
  Profile joystick;
  Profile button;  // pressed where >= 0.5
  // Drive: speed loop (rad/s error -> A), friction wheel and guidewire load.
  double speed_kp_a_s_per_rad = 0.018;
  double speed_ki_a_per_rad = 0.6;
  double current_limit_a = 0.7;
  double wheel_radius_m = 0.010;
  // Load on the guidewire, N: base friction plus friction along the inserted length
  // (assumption, of the order of the LCCA phantom's proximal force).
  double load_base_n = 0.05;
  double load_n_per_m = 2.0;
  uint64_t seed = 1;

  // Defaults of a drive unit (the follower's plant and sensors in teleop_core).
  static SimParams drive();
};

class SimHardware : public Motor, public Encoder, public CurrentSense, public Joystick,
                    public Clock {
 public:
  static constexpr double kStepS = 1.0e-4;

  explicit SimHardware(SimParams params);

  Hardware hardware() { return Hardware{*this, *this, *this, *this, *this}; }

  // Advances the simulation by `dt_s` in steps of kStepS.
  void advance(double dt_s);
  // The hand starts its script again (called at each HELLO).
  void restart_script() { script_t0_s_ = t_s_; }
  // The button held down for `duration_s` from now (a press from outside the script).
  void press(double duration_s) { press_until_s_ = t_s_ + duration_s; }

  void set_current_q(float current_a) override { current_cmd_a_ = current_a; }
  void set_speed(float speed_rad_s) override { speed_cmd_rad_s_ = speed_rad_s; }
  float angle_rad() override { return static_cast<float>(quantised_rad_); }
  float speed_rad_s() override { return static_cast<float>(speed_est_rad_s_); }
  float current_q_a() override;
  float axis() override;
  bool pressed() override;
  uint32_t millis() override { return static_cast<uint32_t>(t_s_ * 1000.0); }

  double t_s() const { return t_s_; }
  double true_angle_rad() const { return theta_rad_; }
  double true_speed_rad_s() const { return omega_rad_s_; }
  double true_current_a() const { return current_a_; }
  // Torque of the motor at current `current_a`, N m.
  double motor_torque_n_m(double current_a) const;
  // The guidewire's load force at the present state, N (drive).
  double load_force_n() const;

 private:
  void step();
  double external_torque_n_m() const;

  SimParams p_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> noise_{0.0, 1.0};
  double t_s_ = 0.0;
  double script_t0_s_ = 0.0;
  double press_until_s_ = -1.0;
  double theta_rad_ = 0.0, omega_rad_s_ = 0.0, current_a_ = 0.0;
  double quantised_rad_ = 0.0, previous_quantised_rad_ = 0.0, speed_est_rad_s_ = 0.0;
  double integral_a_ = 0.0;
  float current_cmd_a_ = 0.0f, speed_cmd_rad_s_ = 0.0f;
  int steps_ = 0;
};

}  // namespace haptic
