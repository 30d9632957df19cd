#include "dataset/flare_export.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <charconv>
#include <chrono>
#include <cmath>
#include <ctime>
#include <numbers>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/parallel_for.h>

#include "common/atomic_file.h"
#include "common/config.h"
#include "common/error.h"
#include "common/exr.h"
#include "common/input_file.h"
#include "common/progress.h"
#include "model/model_renderer.h"

namespace flarekit::dataset {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

constexpr double kDegToRad = std::numbers::pi / 180.0;
// The light's glow is drawn where it reaches this (units of white): below the 8-bit PNG's first
// code (1.5e-4), and it keeps the light's EXR mostly empty, which compresses fast.
constexpr double kGlowFloor = 1e-4;

// ---------------------------------------------------------------------------------------------
// Random numbers: the same on every platform and standard library.

std::uint64_t mix64(std::uint64_t z) {  // SplitMix64's finaliser
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// xoshiro256** (Blackman & Vigna 2018), seeded from SplitMix64 at a state that is a bijection of
// the sample index for a given seed, so that every (seed, index) has its own stream.
class SampleRandom {
 public:
  SampleRandom(std::uint64_t seed, std::uint64_t index) {
    std::uint64_t sm = mix64(mix64(seed + 0x9E3779B97F4A7C15ULL) ^ index);
    for (auto& s : s_) {
      sm += 0x9E3779B97F4A7C15ULL;
      s = mix64(sm);
    }
  }
  std::uint64_t next() {
    const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
    const std::uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 45);
    return result;
  }
  // Uniform in [0, 1): the top 53 bits.
  double unit() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
  double uniform(double a, double b) { return a + (b - a) * unit(); }

 private:
  static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  std::array<std::uint64_t, 4> s_{};
};

// ---------------------------------------------------------------------------------------------

std::optional<long long> parseInteger(std::string_view s) {
  long long v = 0;
  if (s.empty()) return std::nullopt;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
  if (ec != std::errc() || end != s.data() + s.size()) return std::nullopt;
  return v;
}

int digits(long long v) {
  int n = 1;
  while (v >= 10) {
    v /= 10;
    ++n;
  }
  return n;
}

std::string zeroPadded(long long v, int width) {
  std::string s = std::to_string(v);
  if (static_cast<int>(s.size()) < width) s.insert(0, static_cast<size_t>(width) - s.size(), '0');
  return s;
}

// Sorted, merged union of closed intervals.
std::vector<std::pair<double, double>> unionOf(std::vector<std::pair<double, double>> v) {
  std::sort(v.begin(), v.end());
  std::vector<std::pair<double, double>> out;
  for (const auto& r : v) {
    if (!out.empty() && r.first <= out.back().second)
      out.back().second = std::max(out.back().second, r.second);
    else
      out.push_back(r);
  }
  return out;
}

double sampleAngle(const std::vector<std::pair<double, double>>& ranges, double u) {
  double total = 0;
  for (const auto& r : ranges) total += r.second - r.first;
  if (!(total > 0)) {  // only single angles: pick one
    const size_t k = std::min(ranges.size() - 1, static_cast<size_t>(u * static_cast<double>(ranges.size())));
    return ranges[k].first;
  }
  double t = u * total;
  for (const auto& r : ranges) {
    const double len = r.second - r.first;
    if (t < len) return std::min(r.second, r.first + t);
    t -= len;
  }
  return ranges.back().second;
}

bool inFrame(cv::Point2d p, cv::Size size) {
  return p.x >= 0 && p.x < size.width && p.y >= 0 && p.y < size.height;
}

std::string csvField(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) {
    if (c == '"') q += '"';
    q += c;
  }
  return q + "\"";
}

// "3;7;12": a list in one CSV field.
template <typename T>
std::string joined(const std::vector<T>& v) {
  std::string s;
  for (size_t i = 0; i < v.size(); ++i) {
    if (i) s += ';';
    s += std::to_string(v[i]);
  }
  return s;
}

// The sRGB code thresholds: code k + 1 starts at the linear value whose encoding is (k + ½)/255.
const std::array<double, 255>& srgbThresholds() {
  static const std::array<double, 255> t = [] {
    std::array<double, 255> a{};
    for (int k = 0; k < 255; ++k) {
      const double e = (k + 0.5) / 255.0;
      a[static_cast<size_t>(k)] = e <= 0.04045 ? e / 12.92 : std::pow((e + 0.055) / 1.055, 2.4);
    }
    return a;
  }();
  return t;
}

// The code of v: the number of thresholds at or below it. A table indexed by the top 17 bits of
// v's float representation gives the code at each bucket's start; a bucket spans less than the
// ratio of two successive thresholds (0.4 % against at least 0.9 %), so at most one lies inside.
constexpr int kSrgbBucketShift = 15;
constexpr std::uint32_t kSrgbBuckets = 0x3F800000u >> kSrgbBucketShift;  // floats below 1.0

const std::vector<std::uint8_t>& srgbBucketCodes() {
  static const std::vector<std::uint8_t> codes = [] {
    const auto& t = srgbThresholds();
    std::vector<std::uint8_t> a(kSrgbBuckets);
    for (std::uint32_t b = 0; b < kSrgbBuckets; ++b) {
      const float start = std::bit_cast<float>(b << kSrgbBucketShift);
      a[b] = static_cast<std::uint8_t>(std::upper_bound(t.begin(), t.end(), static_cast<double>(start)) - t.begin());
    }
    return a;
  }();
  return codes;
}

std::uint8_t srgbCode(float v, const std::array<double, 255>& t, const std::vector<std::uint8_t>& b) {
  if (!(v > 0)) return 0;  // also NaN
  if (v >= 1) return 255;
  int code = b[std::bit_cast<std::uint32_t>(v) >> kSrgbBucketShift];
  while (code < 255 && static_cast<double>(v) >= t[static_cast<size_t>(code)]) ++code;
  return static_cast<std::uint8_t>(code);
}

// Removes what writers of this shard's samples left when killed (".<name>.tmp-XXXXXX.ext" beside
// the files, common/atomic_file.h): only names of this shard's samples, so shards that share the
// folder and run at the same time never lose each other's temporaries.
void removeOwnTemporaries(const fs::path& folder, const SampleRange& range, long long count, bool descend) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) return;
  const int width = static_cast<int>(sampleName(0, count).size());
  auto ours = [&](std::string_view stem) {
    if (static_cast<int>(stem.size()) != width) return false;
    const auto v = parseInteger(stem);
    return v && *v >= range.begin && *v < range.end;
  };
  std::vector<fs::path> stray;
  for (auto it = fs::directory_iterator(folder, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const std::string n = it->path().filename().string();
    if (descend) {
      if (ours(n) && it->is_directory(ec)) removeOwnTemporaries(it->path(), {0, 0}, 0, false);
      continue;
    }
    const size_t tmp = n.find(".tmp-");
    if (n.size() > 1 && n[0] == '.' && tmp != std::string::npos && (count == 0 || ours(std::string_view(n).substr(1, tmp - 1))))
      stray.push_back(it->path());
  }
  for (const auto& p : stray) fs::remove(p, ec);
}

std::string firstDifference(const json& a, const json& b) {
  for (const auto& [key, value] : b.items())
    if (!a.contains(key) || a[key] != value) return key;
  for (const auto& [key, value] : a.items())
    if (!b.contains(key)) return key;
  return "?";
}

// An 8-bit PNG (1-bit with `bilevel`, for a mask of 0 and 255), atomically, flushed later by the
// caller (syncFileSystem).
void writePng(const fs::path& path, const cv::Mat& image8, bool bilevel = false) {
  writeFileAtomically(
      path,
      [&](const fs::path& temporary) {
        bool ok = false;
        try {
          ok = bilevel ? cv::imwrite(temporary.string(), image8, {cv::IMWRITE_PNG_BILEVEL, 1})
                       : cv::imwrite(temporary.string(), image8);
        } catch (const cv::Exception& e) {
          throw RuntimeError("cannot write " + path.string() + ": " + e.what());
        }
        if (!ok) throw RuntimeError("cannot write " + path.string() + " (check free disk space and permissions)");
      },
      Durability::kDeferred);
}

// CPU time of the calling thread, nanoseconds: what a stage costs, whatever else runs.
long long threadCpuNs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<long long>(t.tv_sec) * 1000000000LL + t.tv_nsec;
}

long long fileSize(const fs::path& p) {
  std::error_code ec;
  const auto n = fs::file_size(p, ec);
  return ec ? 0 : static_cast<long long>(n);
}

}  // namespace

// ---------------------------------------------------------------------------------------------

Shard parseShard(std::string_view text) {
  const size_t slash = text.find('/');
  const auto k = slash == std::string_view::npos ? std::nullopt : parseInteger(text.substr(0, slash));
  const auto n = slash == std::string_view::npos ? std::nullopt : parseInteger(text.substr(slash + 1));
  if (!k || !n || *n < 1 || *n > 1000000 || *k < 1 || *k > *n)
    throw InputError("--shard must be K/N with 1 <= K <= N <= 1000000 (e.g. 2/8), not \"" + std::string(text) + "\"");
  return {static_cast<int>(*k), static_cast<int>(*n)};
}

cv::Size parseSize(std::string_view text) {
  size_t sep = text.find("×");
  size_t sep_len = 2;  // "×" is two bytes in UTF-8
  if (sep == std::string_view::npos) {
    sep = text.find_first_of("xX");
    sep_len = 1;
  }
  const auto w = sep == std::string_view::npos ? std::nullopt : parseInteger(text.substr(0, sep));
  const auto h = sep == std::string_view::npos ? std::nullopt : parseInteger(text.substr(sep + sep_len));
  if (!w || !h || *w < 8 || *h < 8 || *w > 16384 || *h > 16384)
    throw InputError("--size must be W×H (or WxH) with 8 to 16384 pixels each (e.g. 512x512), not \"" +
                     std::string(text) + "\"");
  return {static_cast<int>(*w), static_cast<int>(*h)};
}

SampleRange shardRange(long long count, Shard shard) {
  // count ≤ 1e9 (ExportOptions) and K ≤ N ≤ 1e6: the products fit in 64 bits.
  return {count * (shard.index - 1) / shard.count, count * shard.index / shard.count};
}

bool ExportOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  auto finite = [](double v) { return std::isfinite(v); };
  if (count < 1) return fail("--count must be at least 1, not " + std::to_string(count));
  if (count > 1000000000LL) return fail("--count must be at most 1000000000");
  if (size.width < 8 || size.height < 8 || size.width > 16384 || size.height > 16384)
    return fail("--size must be 8 to 16384 pixels each");
  if (shard.count < 1 || shard.index < 1 || shard.index > shard.count || shard.count > 1000000)
    return fail("--shard must be K/N with 1 <= K <= N <= 1000000");
  if (!finite(ev_min) || !finite(ev_max) || ev_min > ev_max || ev_min < -60 || ev_max > 60)
    return fail("the exposure range must be finite, within [-60, 60] stops, with min <= max");
  if (!finite(mask_threshold) || !(mask_threshold > 0)) return fail("--mask-threshold must be positive");
  if (!finite(core_radius_min) || !(core_radius_min > 0) || !(core_radius_max >= core_radius_min) || core_radius_max > 1)
    return fail("the core radius range must satisfy 0 < min <= max <= 1 (fractions of the width)");
  if (!finite(core_level_min) || !(core_level_min > 0) || !(core_level_max >= core_level_min) || !finite(core_level_max))
    return fail("the core level range must satisfy 0 < min <= max");
  if (!finite(glow_level_min) || !(glow_level_min >= 0) || !(glow_level_max >= glow_level_min) || !finite(glow_level_max))
    return fail("the glow level range must satisfy 0 <= min <= max");
  if (!finite(glow_width_min) || !(glow_width_min > 0) || !(glow_width_max >= glow_width_min) || !finite(glow_width_max))
    return fail("the glow width range must satisfy 0 < min <= max");
  if (threads < 0 || threads > 1024) return fail("--threads must be in [0, 1024]");
  return true;
}

// ---------------------------------------------------------------------------------------------

ExportModel ExportModel::fromModel(model::FlareModel m, std::string file) {
  std::string why;
  if (!m.IsValid(&why)) throw InputError(file, why);
  if (m.ghosts.empty()) throw InputError(file, "the model has no ghosts to export");
  ExportModel e;
  e.file = std::move(file);
  std::vector<std::pair<double, double>> ranges;
  double brightest = 0;
  for (const auto& g : m.ghosts) {
    ranges.emplace_back(g.angle_min_deg, g.angle_max_deg);
    for (int k = 0; k <= 64; ++k) {
      const double a = g.angle_min_deg + (g.angle_max_deg - g.angle_min_deg) * k / 64.0;
      const model::GhostParameters p = g.at(a, m.channels);
      for (int c = 0; c < m.channels; ++c) brightest = std::max({brightest, p.border[c], p.inside[c]});
    }
  }
  e.ranges = unionOf(std::move(ranges));
  if (m.capture.clip_level > 0) {
    e.white = m.capture.clip_level;
    e.white_source = "clip_level";
  } else if (brightest > 0) {
    e.white = 4 * brightest;
    e.white_source = "brightest ghost";
  } else {
    e.white = 1;
    e.white_source = "unit";
  }
  e.model = std::move(m);
  return e;
}

ExportModel ExportModel::load(const fs::path& file) {
  return fromModel(model::FlareModel::load(file), file.string());
}

std::string sampleName(long long index, long long count) {
  return zeroPadded(index, std::max(6, digits(std::max(0LL, count - 1))));
}

cv::Point2d lightPosition(const model::FlareModel& m, double theta_deg, double roll_deg, cv::Size size) {
  const model::CaptureInfo& c = m.capture;
  double r = 0;  // distance of the light's image from the optical axis, capture pixels
  if (c.focal_length_mm > 0) {
    r = c.focal_length_mm * std::tan(theta_deg * kDegToRad) / (c.pixel_pitch_um * 1e-3);
  } else {
    double theta_max = 1e-6;
    for (const auto& g : m.ghosts) theta_max = std::max(theta_max, g.angle_max_deg);
    r = theta_deg / theta_max * (0.5 * c.image_size.width);
  }
  // Positive θ images the light towards −x at roll 0 (docs/design.md); the view turns it with
  // the ghosts.
  return m.viewAt(roll_deg, size).imageFromModel(c.opticalAxis() + cv::Point2d(-r, 0));
}

SampleParameters sampleParameters(const std::vector<ExportModel>& models, const ExportOptions& o, long long index) {
  if (models.empty()) throw std::invalid_argument("sampleParameters: no models");
  SampleParameters s;
  s.index = index;
  s.name = sampleName(index, o.count);
  s.model_index = static_cast<int>(index % static_cast<long long>(models.size()));
  const ExportModel& em = models[static_cast<size_t>(s.model_index)];
  SampleRandom rng(o.seed, static_cast<std::uint64_t>(index));
  // Exposure and light first, the position last: --light-in-frame's retries change nothing else.
  s.exposure_ev = rng.uniform(o.ev_min, o.ev_max);
  s.scale = std::exp2(s.exposure_ev) / em.white;
  const double gain = std::exp2(s.exposure_ev);
  LightSource& l = s.light;
  l.core_radius_px = rng.uniform(o.core_radius_min, o.core_radius_max) * o.size.width;
  l.core_value = gain * std::exp2(rng.uniform(std::log2(o.core_level_min), std::log2(o.core_level_max)));
  l.glow_value = gain * rng.uniform(o.glow_level_min, o.glow_level_max);
  l.glow_width_px = l.core_radius_px * rng.uniform(o.glow_width_min, o.glow_width_max);
  constexpr int kMaxTries = 100000;
  for (int attempt = 0;; ++attempt) {
    s.theta_deg = sampleAngle(em.ranges, rng.unit());
    s.roll_deg = rng.uniform(0, 360);
    l.position_px = lightPosition(em.model, s.theta_deg, s.roll_deg, o.size);
    l.in_frame = inFrame(l.position_px, o.size);
    if (!o.light_in_frame || l.in_frame) break;
    if (attempt + 1 >= kMaxTries)
      throw InputError(em.file, "no light position within its angle range falls inside a " +
                                    std::to_string(o.size.width) + "x" + std::to_string(o.size.height) +
                                    " frame (--light-in-frame)");
  }
  for (const auto& g : em.model.ghostsAt(s.theta_deg)) s.ghost_ids.push_back(g.id);
  return s;
}

SampleImages renderSample(const ExportModel& em, const SampleParameters& s, const ExportOptions& o) {
  const model::FlareModel& m = em.model;
  const int channels = m.channels;
  const cv::Size size = o.size;
  const cv::Rect frame(0, 0, size.width, size.height);
  const model::ViewTransform view = m.viewAt(s.roll_deg, size);
  model::RenderOptions ro;
  ro.parallel = false;  // one sample per thread (TBB runs samples in parallel)

  SampleImages out;
  cv::Mat sum(size, CV_MAKETYPE(CV_32F, channels), cv::Scalar::all(0));
  cv::Mat scratch(size, CV_MAKETYPE(CV_32F, channels), cv::Scalar::all(0));
  // A ghost's mask: where its own exposed value reaches the threshold, i.e. its model value
  // reaches threshold / scale.
  const float threshold = static_cast<float>(o.mask_threshold / s.scale);
  for (const model::GhostAtAngle& g : m.ghostsAt(s.theta_deg)) {
    cv::Mat mask;  // allocated when the ghost shows
    long long pixels = 0;
    const cv::Rect bounds = model::ghostPixelBounds(g.parameters, view) & frame;
    if (bounds.area() > 0) {
      // Rendered over the whole frame (the same tiles and blocks as FlareModel::render) into a
      // blank image, then added: the sum is bit for bit what render() adds ghost by ghost.
      model::addGhosts(std::span<const model::GhostParameters>(&g.parameters, 1), frame, scratch, ro, view);
      cv::Mat alone = scratch(bounds), into = sum(bounds);
      cv::add(into, alone, into);
      cv::Mat peak = alone;
      if (channels == 3) {
        cv::Mat planes[3];
        cv::split(alone, planes);
        peak = cv::max(cv::max(planes[0], planes[1]), planes[2]);
      }
      const cv::Mat box = peak >= threshold;  // 255 where set
      pixels = cv::countNonZero(box);
      alone.setTo(cv::Scalar::all(0));
      if (pixels > 0) {
        mask = cv::Mat(size, CV_8UC1, cv::Scalar(0));
        box.copyTo(mask(bounds));
      }
    }
    out.masks.push_back(std::move(mask));
    out.mask_pixels.push_back(pixels);
  }
  m.pedestalAt(s.theta_deg).addTo(sum, m.capture.image_size, view);

  cv::Mat exposed;
  sum.convertTo(exposed, CV_32F, s.scale);
  if (channels == 1) {
    const cv::Mat planes[3] = {exposed, exposed, exposed};
    cv::merge(planes, 3, out.flare);
  } else {
    out.flare = exposed;
  }

  // The light's stand-in: a white disc (edge anti-aliased over a pixel) and its glow, drawn out to
  // where the glow falls below kGlowFloor.
  const LightSource& l = s.light;
  out.light = cv::Mat(size, CV_32FC3, cv::Scalar::all(0));
  const double inv_w2 = 1.0 / (l.glow_width_px * l.glow_width_px);
  const double glow_reach =
      l.glow_value > kGlowFloor ? l.glow_width_px * std::sqrt(std::pow(l.glow_value / kGlowFloor, 2.0 / 3.0) - 1) : 0;
  const double reach = std::max(glow_reach, l.core_radius_px + 0.5);
  const cv::Rect box = cv::Rect(cv::Point(static_cast<int>(std::floor(std::max(-1.0, l.position_px.x - reach))),
                                          static_cast<int>(std::floor(std::max(-1.0, l.position_px.y - reach)))),
                                cv::Point(static_cast<int>(std::ceil(std::min(size.width + 1.0, l.position_px.x + reach))),
                                          static_cast<int>(std::ceil(std::min(size.height + 1.0, l.position_px.y + reach))))) &
                       frame;
  for (int y = box.y; y < box.y + box.height; ++y) {
    cv::Vec3f* row = out.light.ptr<cv::Vec3f>(y);
    const double dy = y + 0.5 - l.position_px.y;
    for (int x = box.x; x < box.x + box.width; ++x) {
      const double dx = x + 0.5 - l.position_px.x;
      const double r2 = dx * dx + dy * dy;
      const double q = 1.0 + r2 * inv_w2;
      double v = l.glow_value / (q * std::sqrt(q));
      if (v < kGlowFloor) v = 0;
      const double r = std::sqrt(r2);
      if (r < l.core_radius_px + 0.5) v += l.core_value * std::min(1.0, l.core_radius_px + 0.5 - r);
      const float f = static_cast<float>(v);
      row[x] = cv::Vec3f(f, f, f);
    }
  }
  return out;
}

cv::Mat encodeSrgb8(const cv::Mat& linear) {
  CV_Assert(linear.type() == CV_32FC3);
  const auto& t = srgbThresholds();
  const auto& b = srgbBucketCodes();
  cv::Mat out(linear.size(), CV_8UC3);
  for (int y = 0; y < linear.rows; ++y) {
    const cv::Vec3f* src = linear.ptr<cv::Vec3f>(y);
    cv::Vec3b* dst = out.ptr<cv::Vec3b>(y);
    for (int x = 0; x < linear.cols; ++x)
      dst[x] = cv::Vec3b(srgbCode(src[x][2], t, b), srgbCode(src[x][1], t, b), srgbCode(src[x][0], t, b));
  }
  return out;
}

// ---------------------------------------------------------------------------------------------

json sampleJson(const ExportModel& em, const SampleParameters& s, const std::vector<long long>& mask_pixels,
                const ExportOptions& o) {
  json j = json::object();
  j["index"] = s.index;
  j["name"] = s.name;
  j["model"] = em.file;
  j["model_index"] = s.model_index;
  j["seed"] = o.seed;
  j["width"] = o.size.width;
  j["height"] = o.size.height;
  j["theta_deg"] = s.theta_deg;
  j["roll_deg"] = s.roll_deg;
  j["exposure_ev"] = s.exposure_ev;
  j["scale"] = s.scale;
  j["light_x_px"] = s.light.position_px.x;
  j["light_y_px"] = s.light.position_px.y;
  j["light_in_frame"] = s.light.in_frame;
  j["light_core_radius_px"] = s.light.core_radius_px;
  j["light_core_value"] = s.light.core_value;
  j["light_glow_value"] = s.light.glow_value;
  j["light_glow_width_px"] = s.light.glow_width_px;
  j["ghost_ids"] = s.ghost_ids;
  j["mask_pixels"] = mask_pixels;
  return j;
}

std::string csvHeader() {
  return "index,name,model,model_index,seed,width,height,theta_deg,roll_deg,exposure_ev,scale,light_x_px,"
         "light_y_px,light_in_frame,light_core_radius_px,light_core_value,light_glow_value,light_glow_width_px,"
         "ghost_ids,mask_pixels";
}

std::string csvRow(const ExportModel& em, const SampleParameters& s, const std::vector<long long>& mask_pixels,
                   const ExportOptions& o) {
  std::ostringstream r;
  r << s.index << ',' << s.name << ',' << csvField(em.file) << ',' << s.model_index << ',' << o.seed << ','
    << o.size.width << ',' << o.size.height << ',' << numberText(s.theta_deg) << ',' << numberText(s.roll_deg)
    << ',' << numberText(s.exposure_ev) << ',' << numberText(s.scale) << ',' << numberText(s.light.position_px.x)
    << ',' << numberText(s.light.position_px.y) << ',' << (s.light.in_frame ? "true" : "false") << ','
    << numberText(s.light.core_radius_px) << ',' << numberText(s.light.core_value) << ','
    << numberText(s.light.glow_value) << ',' << numberText(s.light.glow_width_px) << ',' << joined(s.ghost_ids)
    << ',' << joined(mask_pixels);
  return r.str();
}

json datasetJson(const std::vector<ExportModel>& models, const ExportOptions& o) {
  json ms = json::array();
  for (const auto& em : models) {
    json ranges = json::array();
    for (const auto& r : em.ranges) ranges.push_back({r.first, r.second});
    ms.push_back({{"file", em.file},
                  {"lens", em.model.capture.lens},
                  {"camera", em.model.capture.camera},
                  {"channels", em.model.channels},
                  {"ghosts", em.model.ghosts.size()},
                  {"angle_ranges_deg", ranges},
                  {"focal_length_mm", em.model.capture.focal_length_mm},
                  {"white", em.white},
                  {"white_source", em.white_source}});
  }
  return {{"format", kDatasetFormat},
          {"version", kDatasetVersion},
          {"count", o.count},
          {"seed", o.seed},
          {"width", o.size.width},
          {"height", o.size.height},
          {"name_digits", sampleName(0, o.count).size()},
          {"exposure_ev", {o.ev_min, o.ev_max}},
          {"mask_threshold", o.mask_threshold},
          {"light_in_frame", o.light_in_frame},
          {"light",
           {{"core_radius_fraction", {o.core_radius_min, o.core_radius_max}},
            {"core_level", {o.core_level_min, o.core_level_max}},
            {"glow_level", {o.glow_level_min, o.glow_level_max}},
            {"glow_width_core_radii", {o.glow_width_min, o.glow_width_max}}}},
          {"folders",
           {{"flare_png", kFlareFolder},
            {"light_png", kLightFolder},
            {"compound_png", kCompoundFolder},
            {"flare_exr", kFlareExrFolder},
            {"light_exr", kLightExrFolder},
            {"masks", kMaskFolder}}},
          {"models", ms}};
}

std::string ExportSummary::BriefReport() const {
  std::ostringstream s;
  s.precision(3);
  s << samples << " samples (" << range.begin << " to " << range.end - 1 << ") in " << out_dir.string() << ": "
    << files << " files, " << std::fixed << bytes / 1e6 << " MB, " << seconds << " s, " << samples_per_s
    << " samples/s on " << threads << " threads";
  return s.str();
}

json toJson(const ExportSummary& s) {
  return {{"out_dir", s.out_dir.string()}, {"first", s.range.begin},  {"end", s.range.end},
          {"samples", s.samples},          {"files", s.files},        {"bytes", s.bytes},
          {"seconds", s.seconds},          {"samples_per_s", s.samples_per_s},
          {"cpu_render_s", s.cpu_render_s}, {"cpu_write_s", s.cpu_write_s},
          {"threads", s.threads},          {"jsonl", s.jsonl.string()}, {"csv", s.csv.string()}};
}

ExportSummary exportFlares(const std::vector<ExportModel>& models, const ExportOptions& o, const fs::path& out) {
  std::string why;
  if (!o.IsValid(&why)) throw InputError(why);
  if (models.empty()) throw InputError("export-flares: give at least one model");
  if (o.light_in_frame) {
    // Every model must be able to put its light in the frame (else each sample would search in vain).
    for (const auto& em : models) {
      bool any = false;
      for (const auto& r : em.ranges)
        for (int a = 0; a <= 64 && !any; ++a)
          for (int p = 0; p < 72 && !any; ++p)
            any = inFrame(lightPosition(em.model, r.first + (r.second - r.first) * a / 64.0, p * 5.0, o.size), o.size);
      if (!any)
        throw InputError(em.file, "no light position within its angle range falls inside a " +
                                      std::to_string(o.size.width) + "x" + std::to_string(o.size.height) +
                                      " frame (--light-in-frame)");
    }
  }

  // The folder and the set it holds.
  createFolder(out);
  const json description = datasetJson(models, o);
  const fs::path manifest = out / "dataset.json";
  if (std::error_code ec; fs::exists(manifest, ec)) {
    json existing;
    try {
      existing = json::parse(readInputFile(manifest));
    } catch (const json::exception&) {
      throw InputError(manifest.string(), "is not a dataset description; export into a new folder");
    }
    if (existing != description)
      throw InputError(manifest.string(), "describes another set (\"" + firstDifference(existing, description) +
                                              "\" differs): export into a new folder, or give the same models "
                                              "and options as the run that made it");
  } else {
    writeJsonFile(manifest, description);
  }
  for (const char* f : {kFlareFolder, kLightFolder, kCompoundFolder, kFlareExrFolder, kLightExrFolder, kMaskFolder})
    createFolder(out / f);

  const SampleRange range = shardRange(o.count, o.shard);
  for (const char* f : {kFlareFolder, kLightFolder, kCompoundFolder, kFlareExrFolder, kLightExrFolder})
    removeOwnTemporaries(out / f, range, o.count, false);
  removeOwnTemporaries(out / kMaskFolder, range, o.count, true);

  std::optional<tbb::global_control> limit;
  if (o.threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, o.threads);

  ExportSummary summary;
  summary.out_dir = out;
  summary.range = range;
  summary.samples = range.size();
  summary.threads = std::min(static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism)),
                             tbb::info::default_concurrency());
  std::vector<std::string> lines(static_cast<size_t>(range.size())), rows(static_cast<size_t>(range.size()));
  std::atomic<long long> files{0}, bytes{0}, render_ns{0}, write_ns{0};
  using clock = std::chrono::steady_clock;

  Progress progress("export-flares", range.size());
  const auto start = clock::now();
  tbb::parallel_for(tbb::blocked_range<long long>(range.begin, range.end, 1), [&](const tbb::blocked_range<long long>& r) {
    for (long long i = r.begin(); i != r.end(); ++i) {
      const long long t0 = threadCpuNs();
      const SampleParameters s = sampleParameters(models, o, i);
      const ExportModel& em = models[static_cast<size_t>(s.model_index)];
      const SampleImages images = renderSample(em, s, o);
      cv::Mat compound = images.flare + images.light;
      const cv::Mat flare8 = encodeSrgb8(images.flare), light8 = encodeSrgb8(images.light),
                    compound8 = encodeSrgb8(compound);
      const long long t1 = threadCpuNs();

      ExrAttributes attributes;
      attributes["flarekit.sample"] = static_cast<int>(s.index);
      attributes["flarekit.model"] = em.file;
      attributes["flarekit.angle_deg"] = s.theta_deg;
      attributes["flarekit.roll_deg"] = s.roll_deg;
      attributes["flarekit.exposure_ev"] = s.exposure_ev;
      attributes["flarekit.scale"] = s.scale;
      attributes["flarekit.light_px"] = cv::Vec2d(s.light.position_px.x, s.light.position_px.y);
      const std::string png = s.name + ".png", exr = s.name + ".exr";
      std::vector<fs::path> written = {out / kFlareFolder / png, out / kLightFolder / png,
                                       out / kCompoundFolder / png, out / kFlareExrFolder / exr,
                                       out / kLightExrFolder / exr};
      writePng(written[0], flare8);
      writePng(written[1], light8);
      writePng(written[2], compound8);
      ExrWriteOptions exr_options;
      exr_options.durability = Durability::kDeferred;
      exr_options.pixel_type = ExrPixelType::kHalf;
      exr_options.zip_level = 1;
      writeExr(written[3], images.flare, attributes, exr_options);
      writeExr(written[4], images.light, attributes, exr_options);
      // Masks of the ghosts that show (an empty mask says nothing a 0 in mask_pixels does not).
      const fs::path mask_dir = out / kMaskFolder / s.name;
      createFolder(mask_dir);
      for (size_t k = 0; k < s.ghost_ids.size(); ++k) {
        if (images.mask_pixels[k] == 0) continue;
        written.push_back(mask_dir / ("ghost_" + std::to_string(s.ghost_ids[k]) + ".png"));
        writePng(written.back(), images.masks[k], true);
      }
      long long b = 0;
      for (const auto& p : written) b += fileSize(p);
      const long long t2 = threadCpuNs();

      const size_t slot = static_cast<size_t>(i - range.begin);
      lines[slot] = jsonText(sampleJson(em, s, images.mask_pixels, o), -1);
      rows[slot] = csvRow(em, s, images.mask_pixels, o);
      files += static_cast<long long>(written.size());
      bytes += b;
      render_ns += t1 - t0;
      write_ns += t2 - t1;
      progress.advance();
    }
  });
  progress.finish();
  summary.seconds = std::chrono::duration<double>(clock::now() - start).count();

  // Every sample on disk before the files that say this run is complete.
  syncFileSystem(out);
  // This run's parameter lines, in index order.
  std::string suffix;
  if (!o.shard.whole()) {
    const int w = digits(o.shard.count);
    suffix = "." + zeroPadded(o.shard.index, w) + "-of-" + zeroPadded(o.shard.count, w);
  }
  summary.jsonl = out / ("samples" + suffix + ".jsonl");
  summary.csv = out / ("samples" + suffix + ".csv");
  std::string jsonl, csv = csvHeader() + "\n";
  for (const auto& l : lines) jsonl += l + "\n";
  for (const auto& r : rows) csv += r + "\n";
  writeTextFileAtomically(summary.jsonl, jsonl);
  writeTextFileAtomically(summary.csv, csv);

  summary.files = files + 2;
  summary.bytes = bytes + static_cast<long long>(jsonl.size() + csv.size());
  summary.samples_per_s = summary.seconds > 0 ? static_cast<double>(summary.samples) / summary.seconds : 0;
  summary.cpu_render_s = render_ns * 1e-9;
  summary.cpu_write_s = write_ns * 1e-9;
  return summary;
}

}  // namespace flarekit::dataset
