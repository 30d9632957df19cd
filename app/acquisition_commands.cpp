// flarekit rig-check, merge, capture, bench merge: parse options, call acquisition/.
#include <signal.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <numeric>
#include <random>

#include <nlohmann/json.hpp>
#include <tbb/global_control.h>
#include <tbb/info.h>

#include "acquisition/capture.h"
#include "acquisition/hdr_merge.h"
#include "acquisition/raw_decode.h"
#include "acquisition/rig.h"
#include "app/commands.h"
#include "common/config.h"
#include "common/error.h"
#include "common/log.h"

namespace flarekit::app {
namespace {

using namespace flarekit::acquisition;
namespace fs = std::filesystem;

// `text` as one word for a POSIX shell: as it is when it holds no special character, else in
// single quotes.
std::string shellQuoted(const std::string& text) {
  const bool plain = !text.empty() && std::all_of(text.begin(), text.end(), [](unsigned char c) {
    return std::isalnum(c) || (c != 0 && std::strchr("_./:=@%+-,", c) != nullptr);
  });
  if (plain) return text;
  std::string out = "'";
  for (char c : text) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

std::atomic<bool> g_stop{false};

extern "C" void onInterrupt(int) {
  if (g_stop.exchange(true)) {
    // Second Ctrl-C: give up at once (files are still whole: every write is atomic).
    signal(SIGINT, SIG_DFL);
    raise(SIGINT);
  }
}

void installInterruptHandler() {
  struct sigaction sa;
  std::memset(&sa, 0, sizeof sa);
  sa.sa_handler = onInterrupt;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

// "0.25,1,4" → {0.25, 1, 4}; InputError naming the option on anything else.
std::vector<double> parseTimes(const std::string& text, const std::string& what) {
  std::vector<double> out;
  if (text.empty()) return out;
  size_t start = 0;
  while (start <= text.size()) {
    const size_t comma = text.find(',', start);
    const std::string item = text.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !(v > 0) || !std::isfinite(v))
      throw InputError(what + ": \"" + item + "\" is not a positive number of seconds (expected e.g. 0.25,1,4)");
    out.push_back(v);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

void registerRigCheck(CLI::App& app) {
  auto rig_arg = std::make_shared<std::string>();
  auto* cmd = app.add_subcommand(
      "rig-check", "Validate a rig file and, for real hardware, find the devices it names");
  cmd->add_option("RIG", *rig_arg, "Rig file or name in rigs/ (e.g. sim-heliar)")->required();
  cmd->callback([rig_arg] {
    const Rig rig = loadRig(findRig(*rig_arg));
    const RigCheckReport report = checkRig(rig);
    for (const auto& line : report.lines) std::cout << line << "\n";
    if (!report.ok)
      throw RuntimeError("rig-check: " + rig.file.string() +
                         ": devices are missing (see above); connect them and run rig-check again");
  });
}

void registerMerge(CLI::App& app) {
  struct Options {
    std::string out;
    std::vector<std::string> inputs;
    std::string exposures_text;
    std::vector<double> exposures;
    std::vector<std::string> darks;
    double black = 0, white = 65535;
    std::string cfa = "mono";
    std::string rig;
    double gain_e_per_dn = 0, read_noise_e = -1;
    double iso = 0;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "merge", "Merge bracketed RAW files (exposure from EXIF) or linear 16-bit TIFF/PNG frames "
               "(with --exposures) into one HDR OpenEXR with a `saturated` mask");
  cmd->add_option("--out", o->out, "Output .exr file")->required();
  cmd->add_option("INPUT", o->inputs, "Bracketed frames of one scene")->required();
  cmd->add_option("--exposures", o->exposures_text,
                  "Exposure times in seconds, one per input, e.g. 0.25,1,4 (required for "
                  "TIFF/PNG; overrides EXIF for RAW)");
  cmd->add_option("--dark", o->darks, "Dark frames, one per input, same exposures (optional)");
  cmd->add_option("--black", o->black, "Black level of TIFF/PNG inputs in DN (default 0)");
  cmd->add_option("--white", o->white, "White level of TIFF/PNG inputs in DN (default 65535)");
  cmd->add_option("--cfa", o->cfa, "Colour filter layout of TIFF/PNG inputs: mono or RGGB, BGGR, "
                                   "GRBG, GBRG (default mono)");
  cmd->add_option("--rig", o->rig, "Take the sensor noise model (gain, read noise) from this rig");
  cmd->add_option("--gain-e-per-dn", o->gain_e_per_dn, "Conversion gain in electrons per DN");
  cmd->add_option("--read-noise-e", o->read_noise_e, "Read noise in electrons RMS");
  cmd->add_option("--iso", o->iso, "ISO the frames were taken at (for the rig's gain)");
  cmd->callback([o] {
    o->exposures = parseTimes(o->exposures_text, "merge: --exposures");
    if (o->inputs.size() < 1) throw InputError("merge: give at least one input frame");
    if (!o->exposures.empty() && o->exposures.size() != o->inputs.size())
      throw InputError("merge: --exposures lists " + std::to_string(o->exposures.size()) +
                       " times for " + std::to_string(o->inputs.size()) + " inputs");
    if (!o->darks.empty() && o->darks.size() != o->inputs.size())
      throw InputError("merge: --dark lists " + std::to_string(o->darks.size()) + " frames for " +
                       std::to_string(o->inputs.size()) + " inputs");
    Cfa cfa;
    if (!parseCfa(o->cfa, &cfa)) throw InputError("merge: --cfa: unknown layout \"" + o->cfa + "\"");
    if (fs::path(o->out).extension() != ".exr")
      throw InputError(o->out + ": the output must be an .exr file");
    auto load = [&](const std::string& file, size_t i) {
      const double t = o->exposures.empty() ? 0 : o->exposures[i];
      if (isLinearImageFile(file)) {
        if (o->exposures.empty())
          throw InputError(file + ": a TIFF/PNG frame has no exposure time: give --exposures");
        return loadLinearImage(file, t, o->black, o->white, cfa);
      }
      RawFrame f = decodeRawFile(file);
      if (t > 0) f.exposure_s = t;
      if (!(f.exposure_s > 0))
        throw InputError(file + ": no exposure time in its EXIF data: give --exposures");
      return f;
    };
    std::vector<RawFrame> frames;
    for (size_t i = 0; i < o->inputs.size(); ++i) frames.push_back(load(o->inputs[i], i));
    std::vector<cv::Mat> darks;
    for (size_t i = 0; i < o->darks.size(); ++i) {
      RawFrame d = load(o->darks[i], i);
      if (d.data.size() != frames[i].data.size())
        throw InputError(o->darks[i] + ": dark frame size differs from " + o->inputs[i]);
      cv::Mat f;
      d.data.convertTo(f, CV_32F);
      darks.push_back(f);
    }
    MergeOptions options;
    const double iso = o->iso > 0 ? o->iso : (frames[0].iso > 0 ? frames[0].iso : 100);
    if (!o->rig.empty()) {
      const Rig rig = loadRig(findRig(o->rig));
      options.gain_e_per_dn = rig.sensor.gainEPerDn(iso);
      options.read_noise_e = rig.sensor.read_noise_e;
    }
    if (o->gain_e_per_dn > 0) options.gain_e_per_dn = o->gain_e_per_dn;
    if (o->read_noise_e >= 0) options.read_noise_e = o->read_noise_e;
    MergeResult result = mergeBracket(frames, options, darks);
    for (const auto& w : result.warnings) logWarning("merge: " + w);
    FrameMetadata meta;
    for (const auto& f : frames) meta.exposures_s.push_back(f.exposure_s);
    meta.iso = frames[0].iso;
    meta.f_number = frames[0].f_number;
    meta.camera = frames[0].camera;
    writeExr(o->out, mergedToExr(result, meta));
    logInfo("merged " + std::to_string(frames.size()) + " exposures of " +
            std::to_string(result.merged.cols) + "x" + std::to_string(result.merged.rows) +
            " photosites into " + o->out + " (" + std::to_string(result.saturated_count) +
            " saturated in every exposure)");
  });
}

void registerCapture(CLI::App& app) {
  struct Options {
    std::string rig = "sim-heliar";
    std::string out;
    double from = 0, to = 0, step = 0;
    std::string exposures_text;
    int dark_frames = -1;
    std::string light_exposures_text;
    double light_nd = 0;
    bool keep_raw = false, resume = false, no_truth = false, half_frames = false;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "capture",
      "Rotate, bracket, merge and store HDR frames with manifest.json (resumable with --resume)");
  cmd->add_option("--rig", o->rig, "Rig file or name in rigs/ (default sim-heliar)");
  cmd->add_option("--out", o->out, "Capture folder")->required();
  cmd->add_option("--from", o->from, "First angle in degrees (default: the rig's)");
  cmd->add_option("--to", o->to, "Last angle in degrees (default: the rig's)");
  cmd->add_option("--step", o->step, "Angle step in degrees (default: the rig's)");
  cmd->add_option("--exposures", o->exposures_text, "Bracket in seconds, e.g. 0.25,1,4");
  cmd->add_option("--dark-frames", o->dark_frames, "Dark frames averaged per exposure");
  cmd->add_option("--light-exposure", o->light_exposures_text,
                  "Light exposures in seconds, e.g. 3e-6,1e-4, taken in each bracket and merged apart "
                  "for the light's flux and stability; 0 = none (default: the rig's light_exposure_s)");
  cmd->add_option("--light-nd", o->light_nd,
                  "The light exposure's declared ND filter attenuation, ≥ 1 (default: the rig's "
                  "light_nd_factor)");
  cmd->add_flag("--keep-raw", o->keep_raw, "Also keep the RAW exposures (raw/*.png)");
  cmd->add_flag("--resume", o->resume, "Continue the capture in --out where it stopped");
  cmd->add_flag("--no-truth", o->no_truth, "Simulated rigs: do not write truth/");
  cmd->add_flag("--half-frames", o->half_frames,
                "Store frames in half precision (small shareable captures)");
  cmd->callback([o, cmd] {
    const Rig rig = loadRig(findRig(o->rig));
    CapturePlan plan = CapturePlan::FromRig(rig);
    if (cmd->count("--from")) plan.from_deg = o->from;
    if (cmd->count("--to")) plan.to_deg = o->to;
    if (cmd->count("--step")) plan.step_deg = o->step;
    if (!o->exposures_text.empty())
      plan.exposures_s = parseTimes(o->exposures_text, "capture: --exposures");
    if (o->dark_frames >= 0) plan.dark_frames = o->dark_frames;
    if (cmd->count("--light-exposure"))
      plan.light_exposures_s = o->light_exposures_text == "0"
                                   ? std::vector<double>{}
                                   : parseTimes(o->light_exposures_text, "capture: --light-exposure");
    if (cmd->count("--light-nd")) plan.light_nd_factor = o->light_nd;
    if (plan.light_exposures_s.empty() && !cmd->count("--light-nd")) plan.light_nd_factor = 1;
    plan.keep_raw = o->keep_raw;
    std::string error;
    if (!plan.IsValid(&error)) throw InputError("capture: " + error);
    checkPlanForRig(rig, plan);  // before touching any device
    RigDevices devices = openRig(rig);
    CaptureOptions options;
    options.resume = o->resume;
    options.write_truth = !o->no_truth;
    options.half_frames = o->half_frames;
    g_stop = false;
    installInterruptHandler();
    options.stop_requested = &g_stop;
    const CaptureSummary summary = runCapture(rig, devices, plan, o->out, options);
    logInfo(summary.BriefReport());
    if (summary.termination == "interrupted") {
      // Every option that shapes the session, so the line works when pasted.
      std::string resume = "flarekit capture --rig " + shellQuoted(rig.file.string()) + " --out " +
                           shellQuoted(o->out) + " --from " + numberText(plan.from_deg) + " --to " +
                           numberText(plan.to_deg) + " --step " + numberText(plan.step_deg) + " --exposures ";
      for (size_t i = 0; i < plan.exposures_s.size(); ++i) resume += (i ? "," : "") + numberText(plan.exposures_s[i]);
      resume += " --dark-frames " + std::to_string(plan.dark_frames);
      if (!plan.light_exposures_s.empty()) {
        resume += " --light-exposure ";
        for (size_t i = 0; i < plan.light_exposures_s.size(); ++i)
          resume += (i ? "," : "") + numberText(plan.light_exposures_s[i]);
        resume += " --light-nd " + numberText(plan.light_nd_factor);
      }
      if (o->keep_raw) resume += " --keep-raw";
      if (o->no_truth) resume += " --no-truth";
      if (o->half_frames) resume += " --half-frames";
      throw Interrupted("capture stopped after frame " +
                        std::to_string(summary.frames_already_done + summary.frames_captured) + " of " +
                        std::to_string(summary.frames_planned) + "; continue with: " + resume + " --resume");
    }
  });
}

void registerBenchMerge(CLI::App& app) {
  struct Options {
    double megapixels = 24;
    int frames = 3;
    int repeat = 5;
    int threads = 0;
    bool json = false;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = benchCommand(app).add_subcommand(
      "merge", "Time the HDR merge of 16-bit frames against a plain memcpy of the same bytes");
  cmd->add_option("--megapixels", o->megapixels, "Frame size in megapixels (default 24)");
  cmd->add_option("--frames", o->frames, "Exposures per bracket (default 3)");
  cmd->add_option("--repeat", o->repeat, "Timed repetitions; the median is reported (default 5)");
  cmd->add_option("--threads", o->threads, "Worker threads (default: all cores)");
  cmd->add_flag("--json", o->json, "Print one JSON object (the default output anyway)");
  cmd->callback([o] {
    if (!(o->megapixels > 0) || o->frames < 1 || o->frames > 16 || o->repeat < 1)
      throw InputError("bench merge: --megapixels must be positive, --frames 1..16, --repeat ≥ 1");
    std::unique_ptr<tbb::global_control> limit;
    if (o->threads > 0)
      limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                    o->threads);
    const int cols = static_cast<int>(std::lround(std::sqrt(o->megapixels * 1e6 * 1.5)));
    const int rows = static_cast<int>(std::lround(o->megapixels * 1e6 / cols));
    // A scene spanning 1e5:1 (a radial fall-off around a bright spot) exposed at 0.25·4^k s.
    std::vector<RawFrame> frames;
    std::mt19937 rng(1);
    cv::Mat scene(rows, cols, CV_32F);
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x) {
        const double r2 = std::pow(x - cols * 0.3, 2) + std::pow(y - rows * 0.5, 2);
        scene.at<float>(y, x) = static_cast<float>(0.02 + 2e3 / (1 + r2 / 400.0));
      }
    for (int k = 0; k < o->frames; ++k) {
      RawFrame f;
      f.exposure_s = 0.25 * std::pow(4.0, k);
      f.black_level = 512;
      f.white_level = 16383;
      cv::Mat dn = scene * (f.exposure_s * 1000 / 4.0) + 512;
      cv::Mat noise(rows, cols, CV_32F);
      cv::randn(noise, 0, 2);
      dn += noise;
      dn.convertTo(f.data, CV_16U);  // saturates at 65535; clip at the white level below
      cv::min(f.data, 16383, f.data);
      frames.push_back(f);
    }
    MergeOptions options;
    options.gain_e_per_dn = 4;
    options.read_noise_e = 3;
    mergeBracket(frames, options);  // warm-up (thread pool, page faults of the output)
    std::vector<double> merge_s, copy_s;
    const size_t bytes_per_frame = static_cast<size_t>(rows) * cols * sizeof(uint16_t);
    std::vector<uint8_t> dst(bytes_per_frame * frames.size());
    std::memset(dst.data(), 1, dst.size());
    for (int r = 0; r < o->repeat; ++r) {
      auto t0 = std::chrono::steady_clock::now();
      MergeResult m = mergeBracket(frames, options);
      auto t1 = std::chrono::steady_clock::now();
      merge_s.push_back(std::chrono::duration<double>(t1 - t0).count());
      t0 = std::chrono::steady_clock::now();
      for (size_t k = 0; k < frames.size(); ++k)
        std::memcpy(dst.data() + k * bytes_per_frame, frames[k].data.data, bytes_per_frame);
      t1 = std::chrono::steady_clock::now();
      copy_s.push_back(std::chrono::duration<double>(t1 - t0).count());
      if (m.merged.empty()) throw RuntimeError("bench merge: empty result");
    }
    auto median = [](std::vector<double> v) {
      std::sort(v.begin(), v.end());
      return v[v.size() / 2];
    };
    const double merge = median(merge_s), copy = median(copy_s);
    nlohmann::json j = {{"benchmark", "merge"},
                        {"width", cols},
                        {"height", rows},
                        {"megapixels", rows * static_cast<double>(cols) / 1e6},
                        {"frames", o->frames},
                        {"input_bytes", bytes_per_frame * frames.size()},
                        {"threads", tbb::global_control::active_value(
                                        tbb::global_control::max_allowed_parallelism)},
                        {"merge_seconds_median", merge},
                        {"merge_seconds_min", *std::min_element(merge_s.begin(), merge_s.end())},
                        {"memcpy_seconds_median", copy},
                        {"merge_to_memcpy_ratio", merge / copy},
                        {"goal_seconds", 0.25},
                        {"repeat", o->repeat}};
    std::cout << jsonText(j) << "\n";
  });
}

}  // namespace

void registerAcquisitionCommands(CLI::App& app) {
  registerRigCheck(app);
  registerMerge(app);
  registerCapture(app);
  registerBenchMerge(app);
}

}  // namespace flarekit::app
