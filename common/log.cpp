#include "common/log.h"

#include <atomic>
#include <iostream>
#include <mutex>

namespace flarekit {
namespace {
std::atomic<LogLevel> g_level{LogLevel::kInfo};
std::mutex g_mutex;

void emit(LogLevel level, std::string_view prefix, std::string_view message) {
  if (level > g_level.load()) return;
  std::lock_guard lock(g_mutex);
  std::cerr << prefix << message << '\n';
}
}  // namespace

void setLogLevel(LogLevel level) { g_level = level; }
LogLevel logLevel() { return g_level.load(); }

void logError(std::string_view m) { emit(LogLevel::kError, "flarekit: error: ", m); }
void logWarning(std::string_view m) { emit(LogLevel::kWarning, "flarekit: warning: ", m); }
void logInfo(std::string_view m) { emit(LogLevel::kInfo, "", m); }
void logDebug(std::string_view m) { emit(LogLevel::kDebug, "debug: ", m); }

}  // namespace flarekit
