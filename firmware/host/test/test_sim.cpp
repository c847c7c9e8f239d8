// The host build's simulated motor against closed forms.
#include <cmath>

#include "runner.h"
#include "sim_hardware.h"

TEST(profiles_are_piecewise_linear_and_held_past_their_ends) {
  haptic::Profile p;
  CHECK(p.parse("0:0,1:0.4,3:0.4,4:0"));
  CHECK_NEAR(p.at(-1.0), 0.0, 1e-12);
  CHECK_NEAR(p.at(0.5), 0.2, 1e-12);
  CHECK_NEAR(p.at(2.0), 0.4, 1e-12);
  CHECK_NEAR(p.at(3.5), 0.2, 1e-12);
  CHECK_NEAR(p.at(9.0), 0.0, 1e-12);
  CHECK(p.parse("0.25"));
  CHECK_NEAR(p.at(7.0), 0.25, 1e-12);
  CHECK(!p.parse("1:0,0.5:1"));  // times must increase
  CHECK(!p.parse("a:1"));
  CHECK(!p.parse(""));
}

TEST(the_encoder_reads_whole_counts_of_a_12_bit_turn) {
  haptic::SimParams params;
  params.hand_aim_rad.parse("0:0,0.5:1.0");
  haptic::SimHardware sim(params);
  const double count = 2.0 * M_PI / 4096.0;
  for (int k = 0; k < 50; ++k) {
    sim.advance(0.01);
    const double counts = sim.angle_rad() / count;
    CHECK_NEAR(counts, std::round(counts), 1e-3);
    CHECK(sim.true_angle_rad() - sim.angle_rad() >= -1e-6);
    CHECK(sim.true_angle_rad() - sim.angle_rad() < count + 1e-6);
  }
  CHECK(sim.angle_rad() > 0.3);  // the hand turned it
}

TEST(the_drive_turns_current_into_torque_with_k_t) {
  haptic::SimHardware sim(haptic::SimParams::drive());
  // tau = K_t i: 0.043 N m/A * 0.1 A = 4.3 mN m
  CHECK_NEAR(sim.motor_torque_n_m(0.1), 4.3e-3, 1e-12);
  CHECK_NEAR(sim.motor_torque_n_m(-0.1), -4.3e-3, 1e-12);
}

TEST(the_drive_holds_a_commanded_speed_with_the_current_its_load_needs) {
  haptic::SimParams params = haptic::SimParams::drive();
  params.current_noise_a = 0.0;
  params.load_n_per_m = 0.0;  // a constant load: base friction only
  haptic::SimHardware sim(params);
  sim.set_speed(5.0f);
  sim.advance(1.0);
  // the speed estimate from whole counts (3.3 counts per ms at 5 rad/s) limit-cycles
  // about the command, as SimpleFOC's does on an AS5600: compared over a second
  double speed = 0.0, current = 0.0;
  for (int k = 0; k < 1000; ++k) {
    sim.advance(1.0e-3);
    speed += sim.speed_rad_s() / 1000.0;
    current += sim.current_q_a() / 1000.0;
  }
  CHECK_NEAR(speed, 5.0, 0.1);
  // steady state: K_t i = b w + tau_c + r F (tanh(...) = 1 at 5 rad/s)
  const double expected_a = (2.0e-5 * 5.0 + 0.8e-3 + 0.010 * 0.05) / 0.043;
  CHECK_NEAR(current, expected_a, 0.1 * expected_a);
}

TEST(current_noise_has_the_ina240s_spread) {
  haptic::SimParams params = haptic::SimParams::drive();
  haptic::SimHardware sim(params);
  double sum = 0.0, sum2 = 0.0;
  const int n = 20000;
  for (int k = 0; k < n; ++k) {
    const double v = sim.current_q_a();
    sum += v;
    sum2 += v * v;
  }
  const double mean = sum / n, sd = std::sqrt(sum2 / n - mean * mean);
  CHECK_NEAR(mean, 0.0, 4.0 * 0.006 / std::sqrt(n));
  CHECK_NEAR(sd, 0.006, 0.0003);
}

TEST(the_dial_renders_eq_14s_torque_and_the_hand_holds_against_it) {
  haptic::SimParams params;
  params.current_noise_a = 0.0;
  params.coulomb_n_m = 0.0;
  haptic::SimHardware sim(params);
  // tau = lever * F(2 mA) = 0.025 * (-0.023155 * 4 + 0.725796 * 2 - 0.019272)
  const double force_n = -0.023155 * 4.0 + 0.725796 * 2.0 - 0.019272;
  CHECK_NEAR(sim.motor_torque_n_m(0.002), 0.025 * force_n, 1e-12);
  CHECK_NEAR(sim.motor_torque_n_m(-0.002), -0.025 * force_n, 1e-12);
  // at rest the hand's grip balances it: theta = tau / k_grip (hand aimed at 0)
  sim.set_current_q(0.002f);
  sim.advance(1.0);
  CHECK_NEAR(sim.true_angle_rad(), 0.025 * force_n / 0.3, 1e-4);
}

TEST(the_clock_counts_milliseconds_of_simulated_time) {
  haptic::SimHardware sim(haptic::SimParams{});
  sim.advance(0.25);
  CHECK(sim.millis() == 250u || sim.millis() == 249u);
}
