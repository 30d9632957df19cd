#include "common/config.h"

#include <cmath>
#include <cstdio>
#include <sstream>

#include <toml++/toml.h>

#include "common/atomic_file.h"
#include "common/input_file.h"
#include "common/error.h"

namespace flarekit {
namespace {

using Json = nlohmann::json;

std::string childPath(const std::string& parent, std::string_view key) {
  return parent.empty() ? std::string(key) : parent + "." + std::string(key);
}

// Converts a TOML value (not a table or array) to JSON, keeping integers apart from floats.
Json tomlValueToJson(const toml::node& node) {
  if (auto* v = node.as_integer()) return Json(v->get());
  if (auto* v = node.as_floating_point()) return Json(v->get());
  if (auto* v = node.as_boolean()) return Json(v->get());
  if (auto* v = node.as_string()) return Json(v->get());
  // Dates and times as ISO 8601 text.
  char buf[64] = "";
  if (auto* v = node.as_date()) {
    const auto& d = v->get();
    std::snprintf(buf, sizeof buf, "%04d-%02d-%02d", int(d.year), int(d.month), int(d.day));
  } else if (auto* t = node.as_time()) {
    const auto& x = t->get();
    std::snprintf(buf, sizeof buf, "%02d:%02d:%02d", int(x.hour), int(x.minute), int(x.second));
  } else if (auto* dt = node.as_date_time()) {
    const auto& d = dt->get().date;
    const auto& x = dt->get().time;
    std::snprintf(buf, sizeof buf, "%04d-%02d-%02dT%02d:%02d:%02d", int(d.year), int(d.month),
                  int(d.day), int(x.hour), int(x.minute), int(x.second));
  }
  return Json(std::string(buf));
}

// "line:column" (1-based) of the byte at `offset`.
std::string lineColumn(std::string_view text, size_t offset) {
  size_t line = 1, col = 1;
  for (size_t i = 0; i < offset && i < text.size(); ++i) {
    if (text[i] == '\n') {
      ++line;
      col = 1;
    } else {
      ++col;
    }
  }
  return std::to_string(line) + ":" + std::to_string(col);
}

// Converts a TOML tree to JSON; InputError when it nests deeper than kMaxJsonDepth.
Json tomlToJson(const toml::node& node, const std::string& file, int depth = 0) {
  if (depth > kMaxJsonDepth)
    throw InputError(file, "not valid TOML here: nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
  if (auto* t = node.as_table()) {
    Json j = Json::object();
    for (const auto& [k, v] : *t) j[std::string(k.str())] = tomlToJson(v, file, depth + 1);
    return j;
  }
  if (auto* a = node.as_array()) {
    Json j = Json::array();
    for (const auto& v : *a) j.push_back(tomlToJson(v, file, depth + 1));
    return j;
  }
  return tomlValueToJson(node);
}

}  // namespace

ConfigNode::ConfigNode(std::shared_ptr<const Json> root, const Json* value, std::string file,
                       std::string key_path)
    : root_(std::move(root)), value_(value), file_(std::move(file)), key_path_(std::move(key_path)) {}

void ConfigNode::fail(std::string_view problem) const {
  if (key_path_.empty()) throw InputError(file_, problem);
  throw InputError(file_, key_path_ + ": " + std::string(problem));
}

std::string ConfigNode::typeName() const {
  switch (value_->type()) {
    case Json::value_t::null: return "null";
    case Json::value_t::object: return "a table";
    case Json::value_t::array: return "an array";
    case Json::value_t::string: return "a string";
    case Json::value_t::boolean: return "a boolean";
    case Json::value_t::number_integer:
    case Json::value_t::number_unsigned: return "an integer";
    case Json::value_t::number_float: return "a number";
    default: return "an unknown value";
  }
}

ConfigNode ConfigNode::operator[](std::string_view key) const {
  auto child = find(key);
  if (!child) {
    std::string path = childPath(key_path_, key);
    throw InputError(file_, "missing key '" + path + "'");
  }
  return *child;
}

std::optional<ConfigNode> ConfigNode::find(std::string_view key) const {
  if (!value_->is_object()) {
    if (value_->is_null()) return std::nullopt;
    fail("must be a table, got " + typeName());
  }
  auto it = value_->find(key);
  if (it == value_->end() || it->is_null()) return std::nullopt;
  return ConfigNode(root_, &*it, file_, childPath(key_path_, key));
}

ConfigNode ConfigNode::operator[](size_t index) const {
  if (!value_->is_array()) fail("must be an array, got " + typeName());
  if (index >= value_->size()) fail("has no element " + std::to_string(index));
  return ConfigNode(root_, &(*value_)[index], file_, key_path_ + "[" + std::to_string(index) + "]");
}

size_t ConfigNode::size() const {
  if (!value_->is_array()) fail("must be an array, got " + typeName());
  return value_->size();
}

std::vector<std::string> ConfigNode::keys() const {
  if (!value_->is_object()) fail("must be a table, got " + typeName());
  std::vector<std::string> out;
  for (auto it = value_->begin(); it != value_->end(); ++it) out.push_back(it.key());
  return out;
}

void ConfigNode::checkKnownKeys(const std::vector<std::string>& known) const {
  for (const auto& k : keys()) {
    bool ok = false;
    for (const auto& n : known) ok = ok || n == k;
    if (!ok) {
      std::string list;
      for (const auto& n : known) list += (list.empty() ? "" : ", ") + n;
      throw InputError(file_, "unknown key '" + childPath(key_path_, k) + "' (known here: " + list + ")");
    }
  }
}

double ConfigNode::number() const {
  if (!value_->is_number()) fail("must be a number, got " + typeName());
  double v = value_->get<double>();
  if (!std::isfinite(v)) fail("must be a finite number");
  return v;
}

long long ConfigNode::integer() const {
  if (value_->is_number_integer()) return value_->get<long long>();
  if (value_->is_number_unsigned()) return static_cast<long long>(value_->get<unsigned long long>());
  if (value_->is_number_float()) {
    double v = value_->get<double>();
    if (std::isfinite(v) && v == std::floor(v) && std::fabs(v) < 9e15) return static_cast<long long>(v);
  }
  fail("must be an integer, got " + typeName());
}

std::string ConfigNode::string() const {
  if (!value_->is_string()) fail("must be a string, got " + typeName());
  return value_->get<std::string>();
}

bool ConfigNode::boolean() const {
  if (!value_->is_boolean()) fail("must be true or false, got " + typeName());
  return value_->get<bool>();
}

std::vector<double> ConfigNode::numbers() const {
  std::vector<double> out;
  for (size_t i = 0; i < size(); ++i) out.push_back((*this)[i].number());
  return out;
}

double ConfigNode::number(std::string_view key, double fallback) const {
  auto c = find(key);
  return c ? c->number() : fallback;
}
long long ConfigNode::integer(std::string_view key, long long fallback) const {
  auto c = find(key);
  return c ? c->integer() : fallback;
}
std::string ConfigNode::string(std::string_view key, const std::string& fallback) const {
  auto c = find(key);
  return c ? c->string() : fallback;
}
bool ConfigNode::boolean(std::string_view key, bool fallback) const {
  auto c = find(key);
  return c ? c->boolean() : fallback;
}

void checkJsonDepth(std::string_view text, const std::string& file) {
  int depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxJsonDepth)
        throw InputError(file + ":" + lineColumn(text, i),
                         "not valid JSON: nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
}

ConfigNode parseJson(std::string_view text, const std::string& file) {
  checkJsonDepth(text, file);
  auto root = std::make_shared<Json>();
  try {
    *root = Json::parse(text.begin(), text.end());
  } catch (const Json::parse_error& e) {
    std::string what = e.what();
    auto pos = what.find("] ");
    if (pos != std::string::npos) what = what.substr(pos + 2);
    throw InputError(file + ":" + lineColumn(text, e.byte > 0 ? e.byte - 1 : 0), "not valid JSON: " + what);
  } catch (const Json::exception& e) {
    // Other parser failures, e.g. a number too large for a double (1e999).
    std::string what = e.what();
    auto pos = what.find("] ");
    if (pos != std::string::npos) what = what.substr(pos + 2);
    throw InputError(file, "not valid JSON: " + what);
  }
  const Json* value = root.get();
  return ConfigNode(root, value, file, "");
}

ConfigNode loadJsonFile(const std::filesystem::path& path) {
  return parseJson(readInputFile(path), path.string());
}

ConfigNode parseToml(std::string_view text, const std::string& file) {
  toml::table table;
  try {
    table = toml::parse(text, file);
  } catch (const toml::parse_error& e) {
    const auto& b = e.source().begin;
    throw InputError(file + ":" + std::to_string(b.line) + ":" + std::to_string(b.column),
                     "not valid TOML: " + std::string(e.description()));
  }
  auto root = std::make_shared<Json>(tomlToJson(table, file));
  const Json* value = root.get();
  return ConfigNode(root, value, file, "");
}

ConfigNode loadTomlFile(const std::filesystem::path& path) {
  return parseToml(readInputFile(path), path.string());
}

int checkFormat(const ConfigNode& root, std::string_view format, int max_version) {
  if (!root.isObject()) root.fail("must hold a JSON object at the top");
  auto f = root.find("format");
  if (!f) root.fail("has no \"format\" (expected \"" + std::string(format) + "\")");
  if (f->string() != format)
    f->fail("is \"" + f->string() + "\", expected \"" + std::string(format) + "\"");
  auto v = root.find("version");
  if (!v) root.fail("has no integer \"version\"");
  if (!v->json().is_number_integer() && !v->json().is_number_unsigned()) v->fail("must be an integer");
  long long version = v->integer();
  if (version < 1 || version > max_version)
    v->fail(std::to_string(version) + " is not supported (this FlareKit reads " + std::string(format) +
            " versions 1 to " + std::to_string(max_version) + ")");
  return static_cast<int>(version);
}

std::string jsonText(const nlohmann::json& value, int indent) {
  return value.dump(indent, ' ', false, Json::error_handler_t::replace);
}

void writeJsonFile(const std::filesystem::path& path, const nlohmann::json& value) {
  writeTextFileAtomically(path, jsonText(value) + "\n");
}

}  // namespace flarekit
