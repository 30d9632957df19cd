// `flarekit view` and `flarekit export-shader` as a user meets them: the viewer in a real browser
// (Debian's chromium, headless, WebGL2 on SwiftShader) draws what `flarekit render` draws, a
// browser without WebGL2 gets a message, and bad models exit 2 with no page written.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/image.h"
#include "common/testing.h"
#include "model/flare_model.h"
#include "tests/cli_util.h"
#include "view/viewer_page.h"

namespace flarekit {
namespace {

using testing::chromiumArgs;
using testing::consoleLines;
using testing::runFlarekit;
using testing::runProgram;
using testing::TempDir;

const std::filesystem::path kSource = FLAREKIT_SOURCE_DIR;

std::string readFile(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Chromium with WebGL2 on its software renderer (the packaged build has no GPU here).
std::vector<std::string> webglArgs(const std::filesystem::path& profile) {
  auto args = chromiumArgs(profile.string());
  args.push_back("--use-angle=swiftshader");
  args.push_back("--enable-unsafe-swiftshader");
  return args;
}

// The page's console messages, less ANGLE's performance notes on the screenshot's read-back
// ("GL Driver Message (OpenGL, Performance, …): GPU stall due to ReadPixels").
std::vector<std::string> pageMessages(const std::string& err) {
  std::vector<std::string> out;
  for (const std::string& line : consoleLines(err))
    if (line.find("GL Driver Message (OpenGL, Performance") == std::string::npos) out.push_back(line);
  return out;
}

struct ViewCase {
  std::string model;  // under the source tree
  double theta_deg, phi_deg, ev;
};

class CliViewAgreement : public ::testing::TestWithParam<ViewCase> {};

// The viewer at a fixed θ, φ and EV against `flarekit render` at the same angles and size after
// the same tone map (common/image.h at the viewer's exposure): the issue's 40 dB.
TEST_P(CliViewAgreement, ViewerDrawsWhatRenderDraws) {
  ASSERT_TRUE(testing::onPath("chromium")) << "chromium (Debian package) is missing; run scripts/setup.sh";
  const ViewCase c = GetParam();
  const std::filesystem::path model_file = kSource / c.model;
  TempDir dir;
  const auto page = dir / "view.html";
  auto r = runFlarekit({"view", model_file.string(), "--out", page.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;

  const cv::Size size(1280, 720);
  auto args = webglArgs(dir / "profile");
  const auto shot = dir / "shot.png";
  args.push_back("--screenshot=" + shot.string());
  args.push_back("--window-size=" + std::to_string(size.width) + "," + std::to_string(size.height));
  args.push_back("--hide-scrollbars");
  args.push_back("file://" + page.string() + "#theta=" + std::to_string(c.theta_deg) +
                 "&phi=" + std::to_string(c.phi_deg) + "&ev=" + std::to_string(c.ev) + "&ui=0");
  auto s = runProgram("chromium", args, 180);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  EXPECT_TRUE(pageMessages(s.err).empty()) << pageMessages(s.err).front();
  const cv::Mat viewer = cv::imread(shot.string());
  ASSERT_EQ(viewer.size(), size) << "screenshot " << shot;

  const model::FlareModel m = model::FlareModel::load(model_file);
  ASSERT_FALSE(m.ghostsAt(c.theta_deg).empty()) << "pick an angle that shows ghosts";
  PreviewOptions tone;
  tone.fixed_scale = view::viewerExposureScale(m);
  tone.exposure_ev = c.ev;
  const cv::Mat rendered = tonemapForDisplay(m.render(c.theta_deg, c.phi_deg, size), tone);
  const double psnr = cv::PSNR(viewer, rendered);
  if (const char* keep = std::getenv("FLAREKIT_KEEP_SCREENSHOT")) {
    cv::imwrite(std::string(keep) + "-viewer.png", viewer);
    cv::imwrite(std::string(keep) + "-render.png", rendered);
  }
  std::cout << c.model << ": viewer against render " << psnr << " dB\n";
  EXPECT_GE(psnr, 40.0) << c.model << " at θ = " << c.theta_deg << "°, φ = " << c.phi_deg << "°";
  // Not a black frame that agrees by being empty: the flare covers a good part of the view.
  cv::Mat grey;
  cv::extractChannel(rendered, grey, 1);
  EXPECT_GT(cv::countNonZero(grey > 8), size.area() / 50) << c.model;
}

// The demo's model (grey), fits of the Tessar on an RGGB sensor and of the Nikon 80–200 mm at 80 mm
// (colour, many ghosts; tests/data/view/README.md says how they were made), and a hand-made
// model of format 1.
INSTANTIATE_TEST_SUITE_P(Models, CliViewAgreement,
                         ::testing::Values(ViewCase{"tests/data/view/demo_model.json", 4.0, -25.0, 1.0},
                                           ViewCase{"tests/data/view/tessar_rggb_model.json", 6.0, 30.0, 0.0},
                                           ViewCase{"tests/data/view/nikon_model.json", 10.0, -40.0, 0.0},
                                           ViewCase{"tests/data/model/example_model.json", 8.0, 35.0, 1.0}));

// A background chosen by the user lies under the flare: its sRGB pixels as linear light, covering
// the window, added before the tone map. The page's own file input cannot be driven headless, so
// the test hands the image to the function the input calls.
TEST(CliView, BackgroundIsCompositedUnderTheFlareBeforeTheToneMap) {
  ASSERT_TRUE(testing::onPath("chromium")) << "chromium (Debian package) is missing; run scripts/setup.sh";
  TempDir dir;
  const auto model_file = kSource / "tests/data/view/demo_model.json";
  auto r = runFlarekit({"view", model_file.string(), "--out", (dir / "view.html").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // A 320×180 background with detail (a gradient and a checkerboard), shown at 4× to cover 1280×720.
  cv::Mat background(180, 320, CV_8UC3);
  for (int y = 0; y < background.rows; ++y)
    for (int x = 0; x < background.cols; ++x)
      background.at<cv::Vec3b>(y, x) = ((x / 20 + y / 20) % 2) ? cv::Vec3b(40, 120, 200) : cv::Vec3b(x * 255 / 319, 60, y * 255 / 179);
  ASSERT_TRUE(cv::imwrite((dir / "background.png").string(), background));
  std::string page = readFile(dir / "view.html");
  const std::string marker = "start();\n</script>";
  ASSERT_NE(page.find(marker), std::string::npos);
  page.replace(page.find(marker), marker.size(),
               "start();\nfetch(\"background.png\").then((r) => r.blob())"
               ".then((b) => loadBackground(new File([b], \"background.png\")));\n</script>");
  std::ofstream(dir / "view.html", std::ios::trunc) << page;

  const double theta = 6, phi = 20;
  auto args = webglArgs(dir / "profile");
  args.push_back("--screenshot=" + (dir / "shot.png").string());
  args.push_back("--window-size=1280,720");
  args.push_back("--hide-scrollbars");
  args.push_back("--virtual-time-budget=10000");  // the image loads after the first frame
  args.push_back("--allow-file-access-from-files");  // for the page's fetch of background.png
  args.push_back("file://" + (dir / "view.html").string() + "#theta=6&phi=20&ev=0&ui=0");
  auto s = runProgram("chromium", args, 180);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  EXPECT_TRUE(pageMessages(s.err).empty()) << pageMessages(s.err).front();
  const cv::Mat shot = cv::imread((dir / "shot.png").string());
  ASSERT_EQ(shot.size(), cv::Size(1280, 720));

  // The same on the CPU: the background decoded from sRGB and scaled up 4× (bilinear, as the GPU
  // samples it), in the viewer's display units (1/scale of the flare's), under the render.
  const model::FlareModel m = model::FlareModel::load(model_file);
  const double scale = view::viewerExposureScale(m);
  cv::Mat linear(background.size(), CV_32FC3);
  for (int y = 0; y < background.rows; ++y)
    for (int x = 0; x < background.cols; ++x)
      for (int c = 0; c < 3; ++c) {
        const double v = background.at<cv::Vec3b>(y, x)[2 - c] / 255.0;  // BGR to RGB
        linear.at<cv::Vec3f>(y, x)[c] = static_cast<float>(v <= 0.04045 ? v / 12.92 : std::pow((v + 0.055) / 1.055, 2.4));
      }
  cv::Mat shown;
  cv::resize(linear, shown, {1280, 720}, 0, 0, cv::INTER_LINEAR);
  cv::Mat flare = m.render(theta, phi, cv::Size(1280, 720));
  if (flare.channels() == 1) cv::cvtColor(flare, flare, cv::COLOR_GRAY2RGB);
  PreviewOptions tone;
  tone.fixed_scale = scale;
  const cv::Mat expected = tonemapForDisplay(flare + shown / scale, tone);
  const double psnr = cv::PSNR(shot, expected);
  std::cout << "viewer with a background against the CPU composite " << psnr << " dB\n";
  EXPECT_GE(psnr, 40.0);
  // The flare alone would not agree: the background shows.
  EXPECT_LT(cv::PSNR(shot, tonemapForDisplay(flare, tone)), 30.0);
}

// A browser without WebGL2 shows a message in place of a blank canvas.
TEST(CliView, ABrowserWithoutWebgl2GetsAMessage) {
  ASSERT_TRUE(testing::onPath("chromium")) << "chromium (Debian package) is missing; run scripts/setup.sh";
  TempDir dir;
  const auto page = dir / "view.html";
  auto r = runFlarekit({"view", (kSource / "tests/data/model/example_model.json").string(), "--out", page.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto args = chromiumArgs((dir / "profile").string());
  args.push_back("--disable-3d-apis");
  args.push_back("--dump-dom");
  args.push_back("file://" + page.string());
  auto dom = runProgram("chromium", args, 120);
  ASSERT_EQ(dom.exit_code, 0) << dom.err;
  EXPECT_TRUE(pageMessages(dom.err).empty()) << pageMessages(dom.err).front();
  EXPECT_NE(dom.out.find("This viewer needs WebGL2"), std::string::npos);
}

// export-shader writes the library with the model's coefficients and flare(); the viewer's page
// carries the same text.
TEST(CliView, ExportShaderWritesTheLibraryTheViewerDraws) {
  TempDir dir;
  const auto model_file = kSource / "tests/data/model/example_model.json";
  auto r = runFlarekit({"export-shader", model_file.string(), "--out", (dir / "flare.glsl").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string glsl = readFile(dir / "flare.glsl");
  EXPECT_NE(glsl.find("vec3 flare(vec2 uv, float theta, float phi)"), std::string::npos);
  EXPECT_NE(glsl.find("const int FLARE_GHOSTS = " +
                      std::to_string(model::FlareModel::load(model_file).ghosts.size()) + ";"),
            std::string::npos);
  r = runFlarekit({"view", model_file.string(), "--out", (dir / "view.html").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string page = readFile(dir / "view.html");
  // The page holds the library as a JSON string: compare one line that needs no escaping.
  const std::string line = glsl.substr(glsl.find("const float FLARE_COEFFICIENTS"), 60);
  EXPECT_NE(page.find(line), std::string::npos) << line;
}

// What an engine does with export-shader's file: one full-screen pass calling flare(uv, θ, φ) at
// every pixel, tone-mapped as flarekit's pictures are. The page is the test's own.
std::string enginePage(const std::string& glsl, double theta, double phi, double scale) {
  return R"(<!doctype html><html><body style="margin:0;overflow:hidden"><canvas id="c" width="640" height="360"></canvas>
<script type="x-shader/x-fragment" id="fs">#version 300 es
precision highp float;
precision highp int;
)" + glsl + R"(
out vec4 color;
float encode(float v) { v = v / (1.0 + v); return v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055; }
void main() {
  vec2 size = vec2(640.0, 360.0), pixel = vec2(gl_FragCoord.x, size.y - gl_FragCoord.y);
  vec3 v = flare((pixel - 0.5 * size) / size.x, )" + std::to_string(theta) + ", " + std::to_string(phi) + R"() * )" +
         std::to_string(scale) + R"(;
  color = vec4(encode(v.r), encode(v.g), encode(v.b), 1.0);
}</script>
<script>
const gl = document.getElementById("c").getContext("webgl2");
const p = gl.createProgram();
for (const [type, text] of [[gl.VERTEX_SHADER, "#version 300 es\nvoid main() { gl_Position = vec4(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0, 0.0, 1.0); }"],
                            [gl.FRAGMENT_SHADER, document.getElementById("fs").textContent]]) {
  const s = gl.createShader(type);
  gl.shaderSource(s, text);
  gl.compileShader(s);
  if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) console.log("compile: " + gl.getShaderInfoLog(s));
  gl.attachShader(p, s);
}
gl.linkProgram(p);
gl.useProgram(p);
gl.drawArrays(gl.TRIANGLES, 0, 3);
</script></body></html>)";
}

TEST(CliView, ExportedFlareFunctionDrawsWhatRenderDraws) {
  ASSERT_TRUE(testing::onPath("chromium")) << "chromium (Debian package) is missing; run scripts/setup.sh";
  TempDir dir;
  const auto model_file = kSource / "tests/data/view/tessar_rggb_model.json";
  auto r = runFlarekit({"export-shader", model_file.string(), "--out", (dir / "flare.glsl").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const model::FlareModel m = model::FlareModel::load(model_file);
  const double theta = 7, phi = 150, scale = view::viewerExposureScale(m);
  std::ofstream(dir / "engine.html") << enginePage(readFile(dir / "flare.glsl"), theta, phi, scale);
  auto args = webglArgs(dir / "profile");
  args.push_back("--screenshot=" + (dir / "shot.png").string());
  args.push_back("--window-size=640,360");
  args.push_back("--hide-scrollbars");
  args.push_back("file://" + (dir / "engine.html").string());
  auto s = runProgram("chromium", args, 180);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  EXPECT_TRUE(pageMessages(s.err).empty()) << pageMessages(s.err).front();
  const cv::Mat shot = cv::imread((dir / "shot.png").string());
  ASSERT_EQ(shot.size(), cv::Size(640, 360));
  PreviewOptions tone;
  tone.fixed_scale = scale;
  const cv::Mat rendered = tonemapForDisplay(m.render(theta, phi, cv::Size(640, 360)), tone);
  const double psnr = cv::PSNR(shot, rendered);
  std::cout << "flare() against render " << psnr << " dB\n";
  EXPECT_GE(psnr, 40.0);
  cv::Mat grey;
  cv::extractChannel(rendered, grey, 1);
  EXPECT_GT(cv::countNonZero(grey > 8), grey.total() / 50);
}

// A model that is malformed or of an unknown version: one line naming the file, exit 2, and no
// page or shader written.
TEST(CliView, BadModelsExit2WithOneLineAndWriteNothing) {
  TempDir dir;
  const auto broken = dir / "broken.json";
  std::ofstream(broken) << "{\"format\": \"flarekit.flare-model\", \"version\": 2, ";
  std::string text = readFile(kSource / "tests/data/model/example_model.json");
  const size_t at = text.find("\"version\"");
  ASSERT_NE(at, std::string::npos);
  text.replace(at, text.find(',', at) - at, "\"version\": 99");
  const auto future = dir / "future.json";
  std::ofstream(future) << text;
  for (const auto& file : {broken, future, dir / "missing.json"})
    for (const std::string command : {"view", "export-shader"}) {
      const auto out = dir / (command + ".out");
      auto r = runFlarekit({command, file.string(), "--out", out.string()});
      EXPECT_EQ(r.exit_code, 2) << command << " " << file << ": " << r.err;
      EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
      EXPECT_NE(r.err.find(file.filename().string()), std::string::npos) << r.err;
      EXPECT_FALSE(std::filesystem::exists(out)) << out;
    }
}

}  // namespace
}  // namespace flarekit
