#pragma once
// Progress for long work (docs/design.md, Conventions): on a terminal a bar with count, rate
// and ETA redrawn in place; when stderr is not a terminal at most one line per 10 %; nothing when
// the log level is below kInfo (--quiet).

#include <atomic>
#include <chrono>
#include <iosfwd>
#include <mutex>
#include <string>

namespace flarekit {

class Progress {
 public:
  // Reports to stderr, as a bar if stderr is a terminal.
  Progress(std::string label, long long total);
  // Reports to `out`; `terminal` chooses the bar or the 10 % lines. For tests and embedding.
  Progress(std::string label, long long total, std::ostream& out, bool terminal);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Adds `n` finished units. Thread-safe; cheap when nothing needs redrawing.
  void advance(long long n = 1);
  // Prints the final state once (also done by the destructor).
  void finish();
  long long done() const { return done_.load(); }

 private:
  void draw(long long done, bool final);

  std::string label_;
  long long total_;
  std::ostream* out_;
  bool terminal_;
  bool enabled_;
  std::atomic<long long> done_{0};
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_{};
  int last_decile_ = -1;
  bool finished_ = false;
};

// "1.5 s", "2 min 03 s", "1 h 02 min".
std::string formatDuration(double seconds);

}  // namespace flarekit
