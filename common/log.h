#pragma once
// Messages to the user on stderr, with levels set once by the CLI (--quiet, --verbose).
// Thread-safe.

#include <string_view>

namespace flarekit {

enum class LogLevel { kError = 0, kWarning = 1, kInfo = 2, kDebug = 3 };

// The most detailed level printed (default kInfo). --quiet sets kWarning, --verbose kDebug.
void setLogLevel(LogLevel level);
LogLevel logLevel();
// True when progress bars and informational lines should be shown.
inline bool showProgress() { return logLevel() >= LogLevel::kInfo; }

void logError(std::string_view message);
void logWarning(std::string_view message);
void logInfo(std::string_view message);
void logDebug(std::string_view message);

}  // namespace flarekit
