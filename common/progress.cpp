#include "common/progress.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "common/log.h"

namespace flarekit {

std::string formatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  char buf[64];
  if (seconds < 60) {
    std::snprintf(buf, sizeof buf, "%.1f s", seconds);
  } else if (seconds < 3600) {
    int s = static_cast<int>(std::lround(seconds));
    std::snprintf(buf, sizeof buf, "%d min %02d s", s / 60, s % 60);
  } else {
    int m = static_cast<int>(std::lround(seconds / 60));
    std::snprintf(buf, sizeof buf, "%d h %02d min", m / 60, m % 60);
  }
  return buf;
}

Progress::Progress(std::string label, long long total)
    : Progress(std::move(label), total, std::cerr, ::isatty(STDERR_FILENO) == 1) {}

Progress::Progress(std::string label, long long total, std::ostream& out, bool terminal)
    : label_(std::move(label)),
      total_(total),
      out_(&out),
      terminal_(terminal),
      enabled_(showProgress()),
      start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() { finish(); }

void Progress::advance(long long n) {
  long long done = done_.fetch_add(n) + n;
  if (!enabled_) return;
  auto now = std::chrono::steady_clock::now();
  if (terminal_) {
    // Redraw at most 10 times a second.
    std::unique_lock lock(mutex_, std::try_to_lock);
    if (!lock || finished_ || now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    draw(done, false);
  } else {
    int decile = total_ > 0 ? static_cast<int>(10 * std::min(done, total_) / total_) : 0;
    std::lock_guard lock(mutex_);
    if (finished_ || decile <= last_decile_ || decile >= 10) return;
    last_decile_ = decile;
    if (decile > 0) draw(done, false);
  }
}

void Progress::finish() {
  std::lock_guard lock(mutex_);
  if (finished_) return;
  finished_ = true;
  if (enabled_) draw(done_.load(), true);
}

void Progress::draw(long long done, bool final) {
  double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  double rate = elapsed > 0 ? done / elapsed : 0;
  double fraction = total_ > 0 ? std::min(1.0, double(done) / double(total_)) : 0;
  std::ostringstream line;
  line << label_ << " ";
  if (terminal_) {
    const int width = 24;
    int filled = static_cast<int>(fraction * width);
    line << "[" << std::string(filled, '#') << std::string(width - filled, '.') << "] ";
  }
  line << done << "/" << total_ << " (" << std::fixed << std::setprecision(1) << 100 * fraction
       << " %), " << std::setprecision(rate < 10 ? 2 : 0) << rate << "/s";
  if (final)
    line << ", took " << formatDuration(elapsed);
  else if (rate > 0)
    line << ", ETA " << formatDuration((total_ - done) / rate);
  if (terminal_)
    *out_ << "\r" << line.str() << "\033[K" << (final ? "\n" : "") << std::flush;
  else
    *out_ << line.str() << "\n" << std::flush;
}

}  // namespace flarekit
