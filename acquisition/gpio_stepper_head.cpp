#include "acquisition/gpio_stepper_head.h"

#include <fcntl.h>
#include <gpiod.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <sstream>

#include "acquisition/stepper_motion.h"
#include "common/log.h"

namespace flarekit::acquisition {
namespace {

constexpr const char* kConsumer = "flarekit";

struct ChipCloser {
  void operator()(gpiod_chip* chip) const { gpiod_chip_close(chip); }
};
// Owner of a gpiod_chip*; closing the chip releases every line requested from it.
using ChipPtr = std::unique_ptr<gpiod_chip, ChipCloser>;

std::string errnoText() { return std::strerror(errno); }

gpiod_chip* openChip(const std::string& name) {
  // gpiod_chip_open_lookup accepts a name ("gpiochip0"), a number, a path or a label.
  return gpiod_chip_open_lookup(name.c_str());
}

timespec toTimespec(double seconds) {
  timespec ts;
  ts.tv_sec = static_cast<time_t>(std::floor(seconds));
  ts.tv_nsec = static_cast<long>((seconds - std::floor(seconds)) * 1e9);
  if (ts.tv_nsec >= 1000000000L) {
    ts.tv_sec += 1;
    ts.tv_nsec -= 1000000000L;
  }
  return ts;
}

double monotonicNow() {
  timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<double>(ts.tv_sec) + ts.tv_nsec * 1e-9;
}

void sleepUntil(double deadline_s) {
  const timespec ts = toTimespec(deadline_s);
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
  }
}

}  // namespace

struct GpioStepperHead::Impl {
  GpioStepperConfig config;
  std::string where;  // rig file, for messages
  ChipPtr chip;
  gpiod_line* step = nullptr;
  gpiod_line* dir = nullptr;
  gpiod_line* enable = nullptr;
  gpiod_line* home = nullptr;
  int home_fd = -1;
  long long position = 0;  // microsteps from the home reference
  bool homed = false;
  int dir_level = -1;  // last DIR level written
  GpioMoveStats stats;

  const StepperGeometry& g() const { return config.geometry; }

  gpiod_line* line(int offset, const char* role) {
    gpiod_line* l = gpiod_chip_get_line(chip.get(), static_cast<unsigned>(offset));
    if (!l)
      throw DeviceError("GPIO chip " + config.chip + " has no line " + std::to_string(offset) +
                            " (" + role + "): check head." + role + "_line in " + where +
                            " against `gpioinfo " + config.chip + "`",
                        false);
    return l;
  }

  void requestOutput(gpiod_line* l, const char* role, int flags, int value) {
    if (gpiod_line_request_output_flags(l, kConsumer, flags, value) < 0)
      throw DeviceError(std::string("cannot request GPIO line ") + role + " on " + config.chip +
                            " as an output (" + errnoText() +
                            "): is it used by another program or a kernel driver?",
                        false);
  }

  void set(gpiod_line* l, int value, const char* role) {
    if (gpiod_line_set_value(l, value) < 0)
      throw DeviceError(std::string("writing GPIO line ") + role + " failed (" + errnoText() + ")",
                        true);
  }

  void open() {
    chip.reset(openChip(config.chip));
    if (!chip)
      throw DeviceError("cannot open GPIO chip \"" + config.chip + "\" (" + errnoText() +
                            "): check head.chip in " + where +
                            " (`gpiodetect` lists the chips) and that you may access /dev/gpiochip*",
                        false);
    step = line(config.step_line, "step");
    dir = line(config.dir_line, "dir");
    requestOutput(step, "step", 0, 0);
    requestOutput(dir, "dir", 0, 0);
    if (config.enable_line >= 0) {
      enable = line(config.enable_line, "enable");
      // Active-low ENABLE: the logical value 1 drives the pin low.
      requestOutput(enable, "enable",
                    config.enable_active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0, 0);
    }
    if (config.home_line >= 0) {
      home = line(config.home_line, "home");
      // A switch that pulls the line low when pressed (the usual wiring, pull-up bias): its press
      // is a falling edge; an active-high switch (pull-down) gives a rising edge.
      int rc;
      if (config.home_active_low)
        rc = gpiod_line_request_falling_edge_events_flags(home, kConsumer,
                                                          GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_UP);
      else
        rc = gpiod_line_request_rising_edge_events_flags(home, kConsumer,
                                                         GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_DOWN);
      if (rc < 0)
        throw DeviceError("cannot request GPIO line " + std::to_string(config.home_line) +
                              " (home switch) for edge events (" + errnoText() + ")",
                          false);
      home_fd = gpiod_line_event_get_fd(home);
      if (home_fd < 0) throw DeviceError("home switch line has no event fd", false);
      const int fl = fcntl(home_fd, F_GETFL);
      if (fl >= 0) fcntl(home_fd, F_SETFL, fl | O_NONBLOCK);
    }
  }

  void setEnabled(bool on) {
    if (enable) set(enable, on ? 1 : 0, "enable");
  }

  // True when a switch event arrived since the last call (non-blocking).
  bool switchEdge() {
    if (home_fd < 0) return false;
    gpiod_line_event event;
    bool seen = false;
    for (int i = 0; i < 64; ++i) {
      if (gpiod_line_event_read_fd(home_fd, &event) < 0) break;  // EAGAIN: nothing pending
      const int press = config.home_active_low ? GPIOD_LINE_EVENT_FALLING_EDGE
                                               : GPIOD_LINE_EVENT_RISING_EDGE;
      if (event.event_type == press) seen = true;
    }
    return seen;
  }

  void setDirection(int sign) {
    const int level = (sign > 0) == config.dir_high_is_positive ? 1 : 0;
    if (level != dir_level) {
      set(dir, level, "dir");
      dir_level = level;
      // DIR set-up time before the next STEP edge.
      sleepUntil(monotonicNow() + config.dir_setup_us * 1e-6);
    }
  }

  // One leg at the ramp's pace; returns the steps made. With `stop_at_switch`, stops after the
  // step at which the home switch reported an edge.
  long long leg(long long steps, int sign, double speed_steps_s, double accel_steps_s2,
                bool stop_at_switch) {
    if (steps <= 0) return 0;
    setDirection(sign);
    const std::vector<double> times = stepTimes(steps, speed_steps_s, accel_steps_s2);
    const double pulse_s = config.step_pulse_us * 1e-6;
    const double start = monotonicNow();
    long long made = 0;
    for (long long k = 0; k < steps; ++k) {
      const double deadline = start + times[static_cast<size_t>(k)];
      sleepUntil(deadline);
      const double late = monotonicNow() - deadline;
      stats.late_max_us = std::max(stats.late_max_us, late * 1e6);
      set(step, 1, "step");
      sleepUntil(monotonicNow() + pulse_s);
      set(step, 0, "step");
      position += sign;
      ++made;
      ++stats.steps;
      if (stop_at_switch && switchEdge()) break;
    }
    stats.duration_s += monotonicNow() - start;
    return made;
  }

  void moveToMicrosteps(long long target) {
    const double per_deg = g().microstepsPerDeg();
    const double speed = g().max_speed_deg_s * per_deg;
    const double accel = g().accel_deg_s2 * per_deg;
    const long long backlash = std::llround(g().backlash_deg * per_deg);
    stats = {};
    setEnabled(true);
    for (long long waypoint : approachWaypoints(position, target, g().approach_sign, backlash)) {
      const long long delta = waypoint - position;
      leg(std::llabs(delta), delta > 0 ? 1 : -1, speed, accel, false);
    }
  }
};

GpioStepperHead::GpioStepperHead(const GpioStepperConfig& config, std::string rig_file)
    : impl_(std::make_unique<Impl>()) {
  impl_->config = config;
  impl_->where = rig_file.empty() ? "the rig file" : rig_file;
  impl_->open();
}

GpioStepperHead::~GpioStepperHead() {
  if (impl_ && impl_->chip) {
    try {
      impl_->setEnabled(false);
    } catch (const DeviceError&) {
      // Closing anyway.
    }
  }
}
GpioStepperHead::GpioStepperHead(GpioStepperHead&&) noexcept = default;
GpioStepperHead& GpioStepperHead::operator=(GpioStepperHead&&) noexcept = default;

std::string GpioStepperHead::describe() const {
  const auto& c = impl_->config;
  std::ostringstream s;
  s << "GPIO stepper on " << c.chip << " (STEP " << c.step_line << ", DIR " << c.dir_line;
  if (c.enable_line >= 0) s << ", ENABLE " << c.enable_line;
  if (c.home_line >= 0) s << ", home switch " << c.home_line;
  s << "; " << c.geometry.full_steps_per_rev << " steps × " << c.geometry.microsteps
    << " microsteps × gear " << c.geometry.gear_ratio << ")";
  return s.str();
}

void GpioStepperHead::home() {
  Impl& m = *impl_;
  const StepperGeometry& g = m.g();
  if (!m.home) {
    logWarning("GPIO stepper: no home switch (head.home_line): the current position is taken as " +
               std::to_string(g.home_angle_deg) + "°");
    m.position = 0;
    m.homed = true;
    return;
  }
  const double per_deg = g.microstepsPerDeg();
  const double speed = g.home_speed_deg_s * per_deg;
  m.stats = {};
  m.setEnabled(true);
  m.switchEdge();  // drop stale events
  // Already on the switch: move off it first.
  if (gpiod_line_get_value(m.home) == (m.config.home_active_low ? 0 : 1))
    m.leg(std::llround(2 * g.home_backoff_deg * per_deg) + 1, -g.home_direction, speed, 1e12, false);
  const long long limit = std::llround(g.home_search_deg * per_deg);
  // Constant homing speed (an acceleration high enough to be a step change).
  const long long made = m.leg(limit, g.home_direction, speed, speed * speed * 2, true);
  if (made >= limit)
    throw DeviceError("homing: no home switch edge on line " + std::to_string(m.config.home_line) +
                          " within " + std::to_string(g.home_search_deg) +
                          "° of travel: check the switch wiring and head.home_direction in " +
                          m.where,
                      false);
  // The switch position is the home reference; back off it.
  m.position = 0;
  m.homed = true;
  const long long backoff = std::llround(g.home_backoff_deg * per_deg);
  if (backoff > 0) m.moveToMicrosteps(-g.home_direction * backoff);
}

void GpioStepperHead::moveTo(double angle_deg) {
  Impl& m = *impl_;
  checkSoftLimits(m.g(), angle_deg, m.where);
  const long long target = microstepsForAngle(m.g(), angle_deg, m.where);
  m.moveToMicrosteps(target);
}

double GpioStepperHead::angleDeg() const {
  return angleForMicrosteps(impl_->g(), impl_->position);
}
long long GpioStepperHead::positionMicrosteps() const { return impl_->position; }
const GpioMoveStats& GpioStepperHead::lastMove() const { return impl_->stats; }

bool probeGpio(const GpioStepperConfig& config, std::vector<std::string>* out) {
  ChipPtr chip(openChip(config.chip));
  if (!chip) {
    out->push_back("MISSING GPIO chip \"" + config.chip + "\" (" + errnoText() +
                   "): `gpiodetect` lists the chips; on a Raspberry Pi 5 the header is on the "
                   "chip labelled pinctrl-rp1");
    return false;
  }
  out->push_back(std::string("found GPIO chip ") + gpiod_chip_name(chip.get()) + " [" +
                 gpiod_chip_label(chip.get()) + "] with " +
                 std::to_string(gpiod_chip_num_lines(chip.get())) + " lines");
  bool ok = true;
  for (auto [role, offset] : {std::pair{"step", config.step_line}, {"dir", config.dir_line},
                              {"enable", config.enable_line}, {"home", config.home_line}}) {
    if (offset < 0) continue;
    gpiod_line* l = gpiod_chip_get_line(chip.get(), static_cast<unsigned>(offset));
    if (!l) {
      out->push_back(std::string("MISSING line ") + std::to_string(offset) + " (" + role + ")");
      ok = false;
    } else if (gpiod_line_is_used(l)) {
      const char* consumer = gpiod_line_consumer(l);
      out->push_back(std::string("BUSY line ") + std::to_string(offset) + " (" + role +
                     ") is used by " + (consumer ? consumer : "the kernel"));
      ok = false;
    } else {
      const char* name = gpiod_line_name(l);
      out->push_back(std::string("line ") + std::to_string(offset) + " (" + role + ") is free" +
                     (name ? std::string(" [") + name + "]" : std::string()));
    }
  }
  return ok;
}

}  // namespace flarekit::acquisition
