#include "view/flare_shader.h"

#include <gtest/gtest.h>

#include <regex>
#include <sstream>

#include "view/viewer_page.h"

namespace flarekit::view {
namespace {

const std::filesystem::path kModel = std::filesystem::path(FLAREKIT_SOURCE_DIR) / "tests/data/model/example_model.json";

// The numbers of the constant array `name` in the shader text.
std::vector<double> arrayValues(const std::string& text, const std::string& name) {
  const size_t start = text.find("const float " + name + "[");
  if (start == std::string::npos) return {};
  const size_t open = text.find("float[](", start), close = text.find(");", open);
  std::string body = text.substr(open + 8, close - open - 8);
  for (char& c : body) if (c == ',') c = ' ';
  std::istringstream in(body);
  std::vector<double> out;
  for (double v; in >> v;) out.push_back(v);
  return out;
}

int intConstant(const std::string& text, const std::string& name) {
  std::smatch m;
  const std::regex re("const int " + name + " = (\\d+);");
  return std::regex_search(text, m, re) ? std::stoi(m[1]) : -1;
}

TEST(FlareShader, BakesEveryCoefficientOfTheModelInItsOrder) {
  const model::FlareModel m = model::FlareModel::load(kModel);
  const std::string glsl = flareShader(m);
  const int terms = intConstant(glsl, "FLARE_TERMS");
  ASSERT_GT(terms, 0);
  EXPECT_EQ(intConstant(glsl, "FLARE_GHOSTS"), static_cast<int>(m.ghosts.size()));
  EXPECT_EQ(intConstant(glsl, "FLARE_PARAMETERS"), model::parameterCount(m.channels));
  const std::vector<double> baked = arrayValues(glsl, "FLARE_COEFFICIENTS");
  ASSERT_EQ(baked.size(), m.ghosts.size() * model::parameterCount(m.channels) * terms);
  size_t i = 0;
  for (const auto& g : m.ghosts)
    for (const auto& p : g.parameters)
      for (int k = 0; k < terms; ++k, ++i) {
        const double want = k < static_cast<int>(p.coefficients.size()) ? p.coefficients[k] : 0.0;
        EXPECT_EQ(static_cast<float>(baked[i]), static_cast<float>(want)) << "ghost " << g.id << " term " << k;
      }
}

TEST(FlareShader, AModelWithoutGhostsDeclaresArraysGlslAccepts) {
  model::FlareModel m = model::FlareModel::load(kModel);
  m.ghosts.clear();
  m.pedestal.reset();
  const std::string glsl = flareShader(m);
  EXPECT_EQ(intConstant(glsl, "FLARE_GHOSTS"), 0);
  // GLSL has no zero-sized arrays: one unused element each.
  EXPECT_EQ(arrayValues(glsl, "FLARE_COEFFICIENTS").size(), 1u);
  EXPECT_EQ(arrayValues(glsl, "FLARE_PEDESTAL_COEFFICIENTS").size(), 1u);
  EXPECT_NE(glsl.find("const bool FLARE_HAS_PEDESTAL = false;"), std::string::npos);
}

TEST(FlareShader, NamesFromTheModelFileStayInsideTheirCommentAndThePage) {
  model::FlareModel m = model::FlareModel::load(kModel);
  m.capture.lens = "lens\n</script><b>";
  const std::string glsl = flareShader(m);
  const std::string first = glsl.substr(0, glsl.find('\n'));
  EXPECT_NE(first.find("lens"), std::string::npos);
  EXPECT_EQ(glsl.find("</"), std::string::npos);
  const std::string page = viewerPage(m);
  // The model's data sits in one <script> element: the name cannot close it.
  EXPECT_EQ(page.find("</script><b>"), std::string::npos);
  EXPECT_EQ(page.find("FLAREKIT_DATA"), std::string::npos);
}

}  // namespace
}  // namespace flarekit::view
