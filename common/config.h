#pragma once
// JSON and TOML documents with errors that name the file and the key.
//
// Both formats load into one tree (TOML tables become JSON objects), read through ConfigNode,
// which remembers its file and key path: a wrong value reads
//   "rigs/sim.toml: head.steps_per_rev: must be a positive integer, got -3".
// Syntax errors name the line: "lens.json:12:5: syntax error ...".

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

namespace flarekit {

class ConfigNode {
 public:
  ConfigNode(std::shared_ptr<const nlohmann::json> root, const nlohmann::json* value,
             std::string file, std::string key_path);

  // Child by key; InputError "missing key" when absent or when this is not a table.
  ConfigNode operator[](std::string_view key) const;
  // Array element; InputError when out of range or not an array.
  ConfigNode operator[](size_t index) const;
  // Child by key, or nullopt when absent (or null).
  std::optional<ConfigNode> find(std::string_view key) const;
  bool has(std::string_view key) const { return find(key).has_value(); }

  bool isNull() const { return value_->is_null(); }
  bool isArray() const { return value_->is_array(); }
  bool isObject() const { return value_->is_object(); }
  // Number of elements of an array (InputError if not an array).
  size_t size() const;
  // Keys of a table, in file order where the format keeps it.
  std::vector<std::string> keys() const;
  // InputError naming the first key of this table that is not in `known` (catches typos).
  void checkKnownKeys(const std::vector<std::string>& known) const;

  // Typed values; InputError naming the key when the type is wrong or a number is not finite.
  double number() const;
  long long integer() const;
  std::string string() const;
  bool boolean() const;
  std::vector<double> numbers() const;

  // Optional children with defaults.
  double number(std::string_view key, double fallback) const;
  long long integer(std::string_view key, long long fallback) const;
  std::string string(std::string_view key, const std::string& fallback) const;
  bool boolean(std::string_view key, bool fallback) const;

  // Throws InputError "<file>: <key path>: <problem>".
  [[noreturn]] void fail(std::string_view problem) const;

  const std::string& file() const { return file_; }
  const std::string& keyPath() const { return key_path_; }
  const nlohmann::json& json() const { return *value_; }

 private:
  std::string typeName() const;

  std::shared_ptr<const nlohmann::json> root_;  // keeps the tree alive
  const nlohmann::json* value_;
  std::string file_;
  std::string key_path_;
};

// Deepest nesting of arrays and tables a JSON or TOML input may have. FlareKit's own formats
// nest at most six levels; the limit keeps a hostile file from exhausting the stack.
inline constexpr int kMaxJsonDepth = 64;

// InputError "<file>:<line>:<column>: ..." when JSON text nests deeper than kMaxJsonDepth. Run
// before parsing: copying, printing and destroying a parsed tree recurse once per level.
// parseJson calls it; it is public for JSON that other parsers read (glTF).
void checkJsonDepth(std::string_view text, const std::string& file);

// Loads a JSON file; InputError naming the file and line on syntax errors.
ConfigNode loadJsonFile(const std::filesystem::path& path);
// Parses JSON text; `file` names it in messages.
ConfigNode parseJson(std::string_view text, const std::string& file);
// Loads a TOML file; InputError naming the file and line on syntax errors.
ConfigNode loadTomlFile(const std::filesystem::path& path);
ConfigNode parseToml(std::string_view text, const std::string& file);

// Checks the top-level "format" name and integer "version" (1 ≤ version ≤ max_version).
// Returns the version.
int checkFormat(const ConfigNode& root, std::string_view format, int max_version);

// JSON as FlareKit prints it: indented by `indent` (-1: one line); bytes that are not UTF-8 (from
// a file name or an EXR attribute) become U+FFFD instead of failing.
std::string jsonText(const nlohmann::json& value, int indent = 2);

// Writes jsonText(value) and a newline atomically.
void writeJsonFile(const std::filesystem::path& path, const nlohmann::json& value);

}  // namespace flarekit
