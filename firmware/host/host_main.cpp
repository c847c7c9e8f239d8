// The host build of a unit: the firmware's protocol and control code on a simulated
// motor, served on a pseudo-terminal as a USB serial unit appears.
//
//   haptic_unit_host --role dial|drive [--link PATH] [--seed N]
//                    [--hand PROFILE] [--joystick PROFILE] [--button PROFILE]
//                    [--corrupt-every N]
//
// It opens a pty, prints `PORT <path>` on stdout (and links PATH to it when given, so
// a restarted unit keeps its port's name), then runs in real time: the simulation
// advances with the wall clock, the unit's control cycle runs every millisecond, and
// every line the host sends is answered at once. Ending the process (a signal) closes
// the pty: the host sees an unplugged unit. PROFILE is "t0:v0,t1:v1,..." (s:value,
// linear between the points, restarted at each HELLO) or one value: the hand's aimed
// dial angle in rad, the joystick's axis in [-1, 1] and its button (pressed where the
// profile is 0.5 or more). --corrupt-every N garbles every
// Nth state line on the wire (its angle field overwritten with 9s, its checksum kept),
// as electrical noise would, to test the host's handling. SIGUSR1 presses the dial's
// button (held down for 0.1 s), as the participant does when the tip reaches the target.
#include <fcntl.h>
#include <getopt.h>
#include <poll.h>
#include <signal.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "sim_hardware.h"
#include "unit.h"

namespace {

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }
volatile sig_atomic_t g_press = 0;
void on_press(int) { g_press = 1; }

// How long a press (SIGUSR1) holds the dial's button down, s: a finger's short press.
constexpr double kPressS = 0.1;

struct Options {
  haptic::Role role = haptic::Role::dial;
  std::string link;
  std::string hand = "0";
  std::string joystick = "0";
  std::string button = "0";
  unsigned long long seed = 1;
  long corrupt_every = 0;
};

[[noreturn]] void usage(const char* message) {
  std::fprintf(stderr,
               "haptic_unit_host: %s\nusage: haptic_unit_host --role dial|drive [--link PATH] "
               "[--seed N] [--hand PROFILE] [--joystick PROFILE] [--button PROFILE] "
               "[--corrupt-every N]\n",
               message);
  std::exit(2);
}

Options parse(int argc, char** argv) {
  static const option long_options[] = {{"role", required_argument, nullptr, 'r'},
                                        {"link", required_argument, nullptr, 'l'},
                                        {"seed", required_argument, nullptr, 's'},
                                        {"hand", required_argument, nullptr, 'h'},
                                        {"joystick", required_argument, nullptr, 'j'},
                                        {"button", required_argument, nullptr, 'b'},
                                        {"corrupt-every", required_argument, nullptr, 'c'},
                                        {nullptr, 0, nullptr, 0}};
  Options o;
  int c;
  while ((c = getopt_long(argc, argv, "", long_options, nullptr)) != -1) {
    const std::string value = optarg != nullptr ? optarg : "";
    if (c == 'r' && value == "dial") {
      o.role = haptic::Role::dial;
    } else if (c == 'r' && value == "drive") {
      o.role = haptic::Role::drive;
    } else if (c == 'r') {
      usage(("--role " + value + "; expected dial or drive").c_str());
    } else if (c == 'l') {
      o.link = value;
    } else if (c == 's') {
      o.seed = std::strtoull(value.c_str(), nullptr, 10);
    } else if (c == 'h') {
      o.hand = value;
    } else if (c == 'j') {
      o.joystick = value;
    } else if (c == 'b') {
      o.button = value;
    } else if (c == 'c') {
      o.corrupt_every = std::strtol(value.c_str(), nullptr, 10);
      if (o.corrupt_every < 1) usage("--corrupt-every: expected a count >= 1");
    } else {
      usage("unknown option");
    }
  }
  return o;
}

// A pty's master end, raw, with the slave end held open by this process as well, so
// that the host opening and closing the port (as a serial terminal does) never hangs up
// the master.
int open_pty(std::string& slave_path, int& slave_fd) {
  const int master = posix_openpt(O_RDWR | O_NOCTTY);
  if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0) return -1;
  const char* name = ptsname(master);
  if (name == nullptr) return -1;
  slave_path = name;
  slave_fd = open(name, O_RDWR | O_NOCTTY);
  if (slave_fd < 0) return -1;
  termios raw{};
  tcgetattr(slave_fd, &raw);
  cfmakeraw(&raw);
  tcsetattr(slave_fd, TCSANOW, &raw);
  return master;
}

// Overwrites the angle field of a framed state line with 9s (the checksum stays).
void garble_angle(char* line) {
  char* field = std::strchr(line, ' ');            // after "S"
  field = field != nullptr ? std::strchr(field + 1, ' ') : nullptr;  // after the clock
  if (field == nullptr) return;
  for (char* c = field + 1; *c != ' ' && *c != '\0'; ++c) {
    if (*c >= '0' && *c <= '8') *c = '9';
  }
}

double now_s() {
  using clock = std::chrono::steady_clock;
  return std::chrono::duration<double>(clock::now().time_since_epoch()).count();
}

void write_all(int fd, const char* data, std::size_t n) {
  while (n > 0) {
    const ssize_t written = write(fd, data, n);
    if (written < 0) {
      if (errno == EINTR || errno == EAGAIN) continue;
      return;
    }
    data += written;
    n -= static_cast<std::size_t>(written);
  }
}

}  // namespace

int main(int argc, char** argv) {
  const Options options = parse(argc, argv);
  haptic::SimParams params =
      options.role == haptic::Role::drive ? haptic::SimParams::drive() : haptic::SimParams{};
  params.seed = options.seed;
  if (!params.hand_aim_rad.parse(options.hand)) usage("--hand: expected t:value,... or a value");
  if (!params.joystick.parse(options.joystick)) {
    usage("--joystick: expected t:value,... or a value");
  }
  if (!params.button.parse(options.button)) {
    usage("--button: expected t:value,... or a value (pressed where >= 0.5)");
  }
  haptic::SimHardware sim(params);
  haptic::Unit unit(options.role, sim.hardware(), haptic::Limits{}, HAPTIC_UNIT_VERSION "-host");

  std::string slave_path;
  int slave_fd = -1;
  const int master = open_pty(slave_path, slave_fd);
  if (master < 0) {
    std::fprintf(stderr, "haptic_unit_host: cannot open a pseudo-terminal: %s\n",
                 std::strerror(errno));
    return 1;
  }
  if (!options.link.empty()) {
    unlink(options.link.c_str());
    if (symlink(slave_path.c_str(), options.link.c_str()) != 0) {
      std::fprintf(stderr, "haptic_unit_host: cannot link %s: %s\n", options.link.c_str(),
                   std::strerror(errno));
      return 1;
    }
  }
  signal(SIGTERM, on_signal);
  signal(SIGINT, on_signal);
  signal(SIGHUP, on_signal);
  signal(SIGUSR1, on_press);
  std::printf("PORT %s\n", slave_path.c_str());
  std::fflush(stdout);

  const double start_s = now_s();
  long state_lines = 0;
  char buffer[256];
  char reply[haptic::kMaxReply];
  while (g_stop == 0) {
    if (g_press != 0) {
      g_press = 0;
      sim.press(kPressS);
    }
    // the simulation and the control cycle catch up with the wall clock
    const double target_s = now_s() - start_s;
    while (sim.t_s() + 1.0e-3 <= target_s) {
      sim.advance(1.0e-3);
      unit.update();
    }
    pollfd fd{master, POLLIN, 0};
    if (poll(&fd, 1, 1) <= 0) continue;
    const ssize_t n = read(master, buffer, sizeof buffer);
    if (n <= 0) continue;
    for (ssize_t k = 0; k < n; ++k) {
      const std::size_t length = unit.receive(buffer[k], reply, sizeof reply);
      if (length == 0) continue;
      if (std::strncmp(reply, "OK dial", 7) == 0 || std::strncmp(reply, "OK drive", 8) == 0) {
        sim.restart_script();  // a HELLO: a new trial, the hand starts again
      }
      if (reply[0] == 'S' && options.corrupt_every > 0 &&
          ++state_lines % options.corrupt_every == 0) {
        garble_angle(reply);
      }
      write_all(master, reply, length);
    }
  }
  if (!options.link.empty()) unlink(options.link.c_str());
  close(slave_fd);
  close(master);
  return 0;
}
