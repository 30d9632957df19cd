#include "common/error.h"

#include <charconv>

namespace flarekit {

std::string oneLine(std::string_view message) {
  std::string out;
  out.reserve(message.size());
  bool space = false;
  for (char c : message) {
    if (c == '\n' || c == '\r' || c == '\t') {
      space = !out.empty();
      continue;
    }
    if (space && c != ' ') out += ' ';
    space = false;
    out += c;
  }
  while (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

namespace {
std::string joined(std::string_view file, std::string_view problem) {
  std::string s;
  s.reserve(file.size() + problem.size() + 2);
  s.append(file).append(": ").append(problem);
  return oneLine(s);
}
}  // namespace

InputError::InputError(std::string_view file, std::string_view problem)
    : std::runtime_error(joined(file, problem)) {}

template <typename T>
std::string shortestText(T v) {
  char buffer[64];
  return std::string(buffer, std::to_chars(buffer, buffer + sizeof buffer, v).ptr);
}

std::string numberText(double v) { return shortestText(v); }
std::string numberText(float v) { return shortestText(v); }

}  // namespace flarekit
