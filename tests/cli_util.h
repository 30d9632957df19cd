#pragma once
// Runs the flarekit binary the way a user would, capturing exit code, stdout and stderr.

#include <algorithm>
#include <string>
#include <vector>

namespace flarekit::testing {

struct CommandResult {
  int exit_code = -1;  // 128 + signal when killed by a signal
  std::string out, err;
};

// Runs `program` with `args` (no shell), waits at most `timeout_s` seconds.
CommandResult runProgram(const std::string& program, const std::vector<std::string>& args,
                         double timeout_s = 600);
// Runs <build>/bin/flarekit.
CommandResult runFlarekit(const std::vector<std::string>& args, double timeout_s = 600);
// True when `program` is on PATH.
bool onPath(const std::string& program);

// Arguments for Debian's chromium in headless mode with a fresh profile at `profile` and no
// network services; the page's URL and what to do with it (--dump-dom, --screenshot=…) follow.
std::vector<std::string> chromiumArgs(const std::string& profile);
// The console messages chromium logged for the page ("INFO:CONSOLE(...)" lines of its stderr).
std::vector<std::string> consoleLines(const std::string& err);

// The number of lines of a command's output (its newlines).
inline int lineCount(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }

}  // namespace flarekit::testing
