#pragma once
// Error tiers (docs/design.md, Conventions): programming errors are assertions; problems with
// what the user gave us are InputError (the CLI exits with 2); failures of hardware, I/O or the
// environment are RuntimeError (the CLI exits with 1). Messages are one line and name the file,
// key or device.

#include <stdexcept>
#include <string>
#include <string_view>

namespace flarekit {

// Collapses a message to one line (library messages sometimes carry newlines).
std::string oneLine(std::string_view message);

// A number for a message: the shortest text that reads back as the same value ("1.5", "1e+308").
// Never throws, also for subnormals, infinities and NaN.
std::string numberText(double v);
std::string numberText(float v);

// Bad input: a file, value or option the user gave is wrong. Exit code 2.
class InputError : public std::runtime_error {
 public:
  explicit InputError(std::string_view message) : std::runtime_error(oneLine(message)) {}
  // "<file>: <problem>"
  InputError(std::string_view file, std::string_view problem);
};

// A failure of I/O, hardware or the environment; the message says what to do. Exit code 1.
class RuntimeError : public std::runtime_error {
 public:
  explicit RuntimeError(std::string_view message) : std::runtime_error(oneLine(message)) {}
};

// Thrown when the user interrupted long work (Ctrl-C) and it stopped cleanly. Exit code 130.
class Interrupted : public std::runtime_error {
 public:
  explicit Interrupted(std::string_view message) : std::runtime_error(oneLine(message)) {}
};

}  // namespace flarekit
