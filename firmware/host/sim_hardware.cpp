#include "sim_hardware.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace haptic {

bool Profile::parse(const std::string& text) {
  points_.clear();
  std::stringstream items(text);
  std::string item;
  while (std::getline(items, item, ',')) {
    const auto colon = item.find(':');
    char* end = nullptr;
    if (colon == std::string::npos) {
      const double value = std::strtod(item.c_str(), &end);
      if (end == item.c_str() || *end != '\0' || !std::isfinite(value)) return false;
      points_.emplace_back(0.0, value);
      continue;
    }
    const std::string t_text = item.substr(0, colon), v_text = item.substr(colon + 1);
    const double t = std::strtod(t_text.c_str(), &end);
    if (end == t_text.c_str() || *end != '\0' || !std::isfinite(t)) return false;
    const double v = std::strtod(v_text.c_str(), &end);
    if (end == v_text.c_str() || *end != '\0' || !std::isfinite(v)) return false;
    if (!points_.empty() && t <= points_.back().first) return false;
    points_.emplace_back(t, v);
  }
  return !points_.empty();
}

double Profile::at(double t_s) const {
  if (points_.empty()) return 0.0;
  if (t_s <= points_.front().first) return points_.front().second;
  for (std::size_t k = 1; k < points_.size(); ++k) {
    const auto [t1, v1] = points_[k];
    if (t_s <= t1) {
      const auto [t0, v0] = points_[k - 1];
      return v0 + (v1 - v0) * (t_s - t0) / (t1 - t0);
    }
  }
  return points_.back().second;
}

SimParams SimParams::drive() {
  SimParams p;
  p.role = Role::drive;
  // teleop_core.follower.params: PlantParams, ControllerParams, SensorParams
  p.inertia_kg_m2 = 5.0e-6;
  p.viscous_n_m_s_per_rad = 2.0e-5;
  p.coulomb_n_m = 0.8e-3;
  p.current_time_constant_s = 1.0 / (2.0 * M_PI * 800.0);  // 800 Hz current loop
  p.current_noise_a = 0.006;
  p.velocity_filter_s = 0.002;
  return p;
}

SimHardware::SimHardware(SimParams params) : p_(std::move(params)), rng_(p_.seed) {}

double SimHardware::motor_torque_n_m(double current_a) const {
  if (p_.role == Role::drive) return p_.torque_constant_n_m_per_a * current_a;
  // the dial: tau = lever * F(|i|), F from eq. 14 (i in mA), odd in the current
  const double i_ma = std::fabs(current_a) * 1000.0;
  const double force_n = std::max(p_.poly_a * i_ma * i_ma + p_.poly_b * i_ma + p_.poly_c, 0.0);
  return std::copysign(p_.lever_arm_m * force_n, current_a);
}

double SimHardware::load_force_n() const {
  const double insertion_m = std::max(theta_rad_ * p_.wheel_radius_m, 0.0);
  const double magnitude = p_.load_base_n + p_.load_n_per_m * insertion_m;
  // friction: opposes the motion, smoothed through zero speed
  return magnitude * std::tanh(omega_rad_s_ * p_.wheel_radius_m / 1.0e-3);
}

double SimHardware::external_torque_n_m() const {
  if (p_.role == Role::drive) return -p_.wheel_radius_m * load_force_n();
  const double aim = p_.hand_aim_rad.at(t_s_ - script_t0_s_);
  return p_.grip_n_m_per_rad * (aim - theta_rad_) - p_.grip_damping_n_m_s_per_rad * omega_rad_s_;
}

void SimHardware::step() {
  const double dt = kStepS;
  double current_cmd = current_cmd_a_;
  if (p_.role == Role::drive && (steps_ % 10) == 0) {
    // SimpleFOC's velocity loop at 1 kHz: PI on the filtered speed, clamped, no windup
    const double error = speed_cmd_rad_s_ - speed_est_rad_s_;
    integral_a_ = std::clamp(integral_a_ + p_.speed_ki_a_per_rad * error * dt * 10.0,
                             -p_.current_limit_a, p_.current_limit_a);
  }
  if (p_.role == Role::drive) {
    const double error = speed_cmd_rad_s_ - speed_est_rad_s_;
    current_cmd = std::clamp(p_.speed_kp_a_s_per_rad * error + integral_a_, -p_.current_limit_a,
                             p_.current_limit_a);
  }
  // the closed current loop as a first-order lag
  current_a_ += (current_cmd - current_a_) * dt / p_.current_time_constant_s;
  // J theta_dd = tau_m - b theta_d - tau_c sgn(theta_d) + tau_ext
  const double friction = p_.coulomb_n_m * std::tanh(omega_rad_s_ / 1.0e-2);
  const double torque = motor_torque_n_m(current_a_) - p_.viscous_n_m_s_per_rad * omega_rad_s_ -
                        friction + external_torque_n_m();
  omega_rad_s_ += torque / p_.inertia_kg_m2 * dt;
  theta_rad_ += omega_rad_s_ * dt;
  t_s_ += dt;
  ++steps_;
  if (steps_ % 10 == 0) {
    // the encoder read and the speed estimate at 1 kHz, as loopFOC()/move() run
    const double count_rad = 2.0 * M_PI / p_.encoder_counts;
    quantised_rad_ = std::floor(theta_rad_ / count_rad) * count_rad;
    const double raw = (quantised_rad_ - previous_quantised_rad_) / (10.0 * dt);
    previous_quantised_rad_ = quantised_rad_;
    const double alpha = p_.velocity_filter_s / (p_.velocity_filter_s + 10.0 * dt);
    speed_est_rad_s_ = alpha * speed_est_rad_s_ + (1.0 - alpha) * raw;
  }
}

void SimHardware::advance(double dt_s) {
  const long n = std::lround(dt_s / kStepS);
  for (long k = 0; k < n; ++k) step();
}

float SimHardware::current_q_a() {
  return static_cast<float>(current_a_ + p_.current_noise_a * noise_(rng_));
}

float SimHardware::axis() {
  if (p_.role != Role::dial) return 0.0f;
  return static_cast<float>(std::clamp(p_.joystick.at(t_s_ - script_t0_s_), -1.0, 1.0));
}

bool SimHardware::pressed() {
  if (p_.role != Role::dial) return false;
  return t_s_ < press_until_s_ || p_.button.at(t_s_ - script_t0_s_) >= 0.5;
}

}  // namespace haptic
