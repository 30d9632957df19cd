#include "common/config.h"

#include <gtest/gtest.h>

#include "common/error.h"
#include "common/testing.h"

namespace flarekit {
namespace {

std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(Config, JsonSyntaxErrorNamesFileAndLine) {
  std::string e = errorOf([] { parseJson("{\n  \"a\": 1,\n  \"b\": tru\n}\n", "lens.json"); });
  EXPECT_EQ(e.rfind("lens.json:3:", 0), 0u) << e;
  EXPECT_NE(e.find("not valid JSON"), std::string::npos) << e;
}

// Deep nesting is refused before parsing, where copying or printing the tree would overflow the stack.
TEST(Config, DeepNestingIsBadInputNamingWhere) {
  const std::string deep = "{\"a\": " + std::string(100000, '[') + std::string(100000, ']') + "}";
  EXPECT_EQ(errorOf([&] { parseJson(deep, "model.json"); }),
            "model.json:1:" + std::to_string(7 + kMaxJsonDepth - 1) + ": not valid JSON: nested deeper than 64 levels");
  // Brackets inside strings are text, not nesting.
  EXPECT_NO_THROW(parseJson("{\"a\": \"" + std::string(1000, '[') + "\\\"\"}", "x.json"));
  const std::string toml = "a = " + std::string(200, '[') + std::string(200, ']') + "\n";
  EXPECT_NE(errorOf([&] { parseToml(toml, "rig.toml"); }).find("rig.toml"), std::string::npos);
}

// Text that is not UTF-8 (a file name, an EXR attribute) prints with U+FFFD instead of failing.
TEST(Config, JsonTextReplacesBytesThatAreNotUtf8) {
  const nlohmann::json j = {{"scene", std::string("scene\xff.json")}};
  EXPECT_EQ(jsonText(j, -1), "{\"scene\":\"scene\xef\xbf\xbd.json\"}");
}

TEST(Config, NumberOverflowIsBadInput) {
  std::string e = errorOf([] { parseJson("{\"x\": 1e999}", "model.json"); });
  EXPECT_EQ(e.rfind("model.json", 0), 0u) << e;
  EXPECT_NE(e.find("not valid JSON"), std::string::npos) << e;
}

TEST(Config, MissingKeyAndWrongTypeNameTheKeyPath) {
  auto root = parseJson(R"({"surfaces": [{"radius": 1.5}, {"radius": "big"}]})", "lens.json");
  EXPECT_DOUBLE_EQ(root["surfaces"][0]["radius"].number(), 1.5);
  EXPECT_EQ(errorOf([&] { root["surfaces"][1]["radius"].number(); }),
            "lens.json: surfaces[1].radius: must be a number, got a string");
  EXPECT_EQ(errorOf([&] { root["surfaces"][0]["thickness"]; }),
            "lens.json: missing key 'surfaces[0].thickness'");
  EXPECT_EQ(errorOf([&] { root["surfaces"][5]; }), "lens.json: surfaces: has no element 5");
  EXPECT_DOUBLE_EQ(root["surfaces"][0].number("thickness", 2.0), 2.0);
  EXPECT_EQ(errorOf([&] { root["surfaces"][0]["radius"].integer(); }),
            "lens.json: surfaces[0].radius: must be an integer, got a number");
}

TEST(Config, UnknownKeysAreReported) {
  auto root = parseJson(R"({"width": 3, "hieght": 4})", "x.json");
  EXPECT_EQ(errorOf([&] { root.checkKnownKeys({"width", "height"}); }),
            "x.json: unknown key 'hieght' (known here: width, height)");
}

TEST(Config, FormatAndVersion) {
  auto good = parseJson(R"({"format": "flarekit.capture", "version": 1})", "m.json");
  EXPECT_EQ(checkFormat(good, "flarekit.capture", 1), 1);
  EXPECT_EQ(errorOf([&] { checkFormat(good, "flarekit.flare-model", 1); }),
            "m.json: format: is \"flarekit.capture\", expected \"flarekit.flare-model\"");
  auto newer = parseJson(R"({"format": "flarekit.capture", "version": 2})", "m.json");
  EXPECT_NE(errorOf([&] { checkFormat(newer, "flarekit.capture", 1); }).find("version: 2 is not supported"),
            std::string::npos);
  auto fractional = parseJson(R"({"format": "flarekit.capture", "version": 1.5})", "m.json");
  EXPECT_EQ(errorOf([&] { checkFormat(fractional, "flarekit.capture", 1); }),
            "m.json: version: must be an integer");
  auto none = parseJson(R"({"version": 1})", "m.json");
  EXPECT_NE(errorOf([&] { checkFormat(none, "flarekit.capture", 1); }).find("has no \"format\""),
            std::string::npos);
  auto array = parseJson(R"([1, 2])", "m.json");
  EXPECT_NE(errorOf([&] { checkFormat(array, "flarekit.capture", 1); }).find("JSON object"),
            std::string::npos);
}

TEST(Config, TomlLoadsIntoTheSameTree) {
  auto root = parseToml("[head]\nsteps = 200\nratio = 2.5\nname = \"sim\"\non = true\n"
                        "list = [1, 2.5]\n",
                        "rig.toml");
  EXPECT_EQ(root["head"]["steps"].integer(), 200);
  EXPECT_DOUBLE_EQ(root["head"]["ratio"].number(), 2.5);
  EXPECT_EQ(root["head"]["name"].string(), "sim");
  EXPECT_TRUE(root["head"]["on"].boolean());
  EXPECT_EQ(root["head"]["list"].numbers(), (std::vector<double>{1, 2.5}));
  EXPECT_EQ(errorOf([&] { root["head"]["ratio"].integer(); }),
            "rig.toml: head.ratio: must be an integer, got a number");
}

TEST(Config, TomlSyntaxErrorNamesLine) {
  std::string e = errorOf([] { parseToml("[head]\nsteps = \n", "rig.toml"); });
  EXPECT_EQ(e.rfind("rig.toml:2:", 0), 0u) << e;
}

TEST(Config, MissingFile) {
  EXPECT_EQ(errorOf([] { loadJsonFile("/nonexistent/x.json"); }), "/nonexistent/x.json: no such file");
  EXPECT_EQ(errorOf([] { loadTomlFile("/nonexistent/x.toml"); }), "/nonexistent/x.toml: no such file");
}

TEST(Config, WriteJsonRoundTrip) {
  testing::TempDir dir;
  nlohmann::json j = {{"format", "flarekit.test"}, {"version", 1}, {"x", 0.1}};
  writeJsonFile(dir / "a.json", j);
  auto back = loadJsonFile(dir / "a.json");
  EXPECT_EQ(back.json(), j);
}

}  // namespace
}  // namespace flarekit
