#pragma once
// Runs the flarekit binary the way a user would, capturing exit code, stdout and stderr.

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

}  // namespace flarekit::testing
