#pragma once
// `flarekit export-flares` (issue 59): training images for flare-removal networks (Wu et al. ICCV
// 2021, "How to train neural networks for flare removal"; Dai et al. NeurIPS 2022, Flare7K, and
// Flare7K++) rendered from fitted flare models (model/flare_model.h). Each sample is one light at a
// random position within a model's angle range, a random roll and a random exposure; it gives the
// flare alone, the light's own image apart, their sum, a mask per ghost and one line of parameters.
// The folder layout and the files are described in docs/datasets.md.
//
// Determinism: sample i's parameters come from (seed, i) alone (a SplitMix64-seeded xoshiro256**
// stream per sample, no std:: distributions, whose results differ between standard libraries), and
// its images from those parameters alone (rendered in one thread each, with TBB across samples), so
// a run writes the same bytes whatever the thread count, and `--shard K/N` writes exactly the files
// of samples [⌊(K−1)·count/N⌋, ⌊K·count/N⌋) that a whole run writes. The parameter lines of a shard
// go to samples.K-of-N.jsonl / .csv; concatenated in K order they are the whole run's samples.jsonl
// (and the CSV's rows).
//
// Sampling (per sample i, in this order):
//   model     models[i mod M] (round robin: every model gets its share)
//   θ         uniform over the union of the model's ghost ranges (never where no ghost exists)
//   φ         uniform in [0°, 360°)
//   exposure  EV uniform in [ev_min, ev_max]: the image is the model's value × 2^EV / white, where
//             white is the model's clip level (the value that clips in its capture frames: EV 0
//             is the capture's own exposure) or, for models that do not record one, 4 × the
//             brightest ghost value (Ib, Ii) over the model's range (the simulated captures' ghosts
//             peak near a quarter of white at EV 0)
//   light     core radius, core level, glow level and width (LightSource below)
// With light_in_frame, (θ, φ) are drawn again until the light's image falls inside the frame.
//
// The light's image: a fitted model holds the ghosts and the pedestal but not the light's own
// image (the fit measures it, fit/horizon.h's LightPattern, to take it out of the frames, and does
// not keep it); predict/ draws no light either. So the light is drawn as a stand-in where the
// model's geometry puts it: the optical axis (capture.optical_axis_px) plus f·tan θ / pitch
// towards −x, turned by φ, as `flarekit view` places it (capture pixels scaled by W / capture
// width; for a model without a focal length θ / θmax × half the capture width, as the viewer
// does). It is a white disc (the core, far above white as a real light's core is) with a glow
// around it that falls off as (1 + (r/w)²)^(−3/2), in the style of Flare7K++'s light-source
// annotations (a core with a tiny glare).
//
// Thread safety: the functions are pure except exportFlares, which writes files.

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "model/flare_model.h"

namespace flarekit::dataset {

inline constexpr char kDatasetFormat[] = "flarekit.flare-dataset";
inline constexpr int kDatasetVersion = 1;

// The folders of an exported set (docs/datasets.md). Every sample has the same file name
// (its zero-padded index) in each.
inline constexpr char kFlareFolder[] = "Flare";                    // flare alone, 8-bit sRGB PNG
inline constexpr char kLightFolder[] = "Light_Source";             // the light alone, PNG
inline constexpr char kCompoundFolder[] = "Compound_Flare";        // flare + light, PNG
inline constexpr char kFlareExrFolder[] = "Flare_EXR";             // flare alone, linear EXR
inline constexpr char kLightExrFolder[] = "Light_Source_EXR";      // the light alone, linear EXR
inline constexpr char kMaskFolder[] = "Mask";                      // Mask/<name>/ghost_<id>.png

// Part K (1-based) of N.
struct Shard {
  int index = 1;
  int count = 1;
  bool whole() const { return count == 1; }
};

// "K/N" with 1 ≤ K ≤ N ≤ 1 000 000; InputError naming --shard otherwise.
Shard parseShard(std::string_view text);
// "W×H" or "WxH" (8 ≤ W, H ≤ 16384); InputError naming --size otherwise.
cv::Size parseSize(std::string_view text);

// Sample indices [begin, end).
struct SampleRange {
  long long begin = 0;
  long long end = 0;
  long long size() const { return end - begin; }
};
// The samples of `shard` in a set of `count`: [⌊(K−1)·count/N⌋, ⌊K·count/N⌋).
SampleRange shardRange(long long count, Shard shard);

struct ExportOptions {
  long long count = 100;        // samples in the whole set (≥ 1)
  cv::Size size{512, 512};      // image size, pixels
  std::uint64_t seed = 1;
  Shard shard;                  // which part this run writes
  double ev_min = -1;           // exposure range, stops relative to the model's white (see above)
  double ev_max = 3;
  // A ghost's mask is set where its own exposed value (largest channel) reaches this, in units of
  // white (default 1/256: about code 13 of the sRGB PNG).
  double mask_threshold = 1.0 / 256;
  bool light_in_frame = false;  // draw (θ, φ) until the light's image lies inside the frame
  // Light stand-in ranges (LightSource): core radius as a fraction of the width, core and glow
  // levels in units of white at EV 0 (log2-uniform for the core), glow width in core radii.
  double core_radius_min = 0.003, core_radius_max = 0.012;
  double core_level_min = 64, core_level_max = 4096;
  double glow_level_min = 0.25, glow_level_max = 2;
  double glow_width_min = 1.5, glow_width_max = 4;
  int threads = 0;              // TBB threads across samples (0 = all cores)

  bool IsValid(std::string* error) const;
};

// One model of the set, loaded and prepared for sampling.
struct ExportModel {
  std::string file;             // as given (recorded in every sample's line)
  model::FlareModel model;
  double white = 0;             // model value that maps to 1.0 at EV 0
  std::string white_source;     // "clip_level" or "brightest ghost"
  std::vector<std::pair<double, double>> ranges;  // disjoint, sorted union of the ghosts' ranges, degrees

  // Loads `file` (InputError "<file>: <problem>" for a missing, unreadable or invalid model, or one
  // without ghosts).
  static ExportModel load(const std::filesystem::path& file);
  // The same for a model in memory; `file` names it.
  static ExportModel fromModel(model::FlareModel model, std::string file);
};

// The light's stand-in image (see the top of this file), in output pixels and exposed values.
struct LightSource {
  cv::Point2d position_px;      // centre of the light's image (may lie outside the frame)
  bool in_frame = false;
  double core_radius_px = 0;
  double core_value = 0;        // linear value of the core (exposure applied)
  double glow_value = 0;        // glow at the centre (exposure applied)
  double glow_width_px = 0;     // w of (1 + (r/w)²)^(−3/2)
};

struct SampleParameters {
  long long index = 0;
  std::string name;             // zero-padded index: the file name in every folder
  int model_index = 0;
  double theta_deg = 0;
  double roll_deg = 0;
  double exposure_ev = 0;
  double scale = 0;             // 2^EV / white: model value → exposed value
  LightSource light;
  std::vector<int> ghost_ids;   // the ghosts the model has at θ, in model order
};

// The file name of sample `index` in a set of `count`: the index zero-padded to at least 6 digits.
std::string sampleName(long long index, long long count);

// The parameters of sample `index` (0 ≤ index < options.count): from (seed, index) alone.
SampleParameters sampleParameters(const std::vector<ExportModel>& models, const ExportOptions& options,
                                  long long index);

// Where the light images at θ, φ in an image of `size` drawn through model.viewAt(φ, size).
cv::Point2d lightPosition(const model::FlareModel& model, double theta_deg, double roll_deg, cv::Size size);

struct SampleImages {
  cv::Mat flare;                // CV_32FC3, exposed linear values: ghosts and pedestal
  cv::Mat light;                // CV_32FC3, the light's stand-in
  std::vector<cv::Mat> masks;   // CV_8UC1 (0 / 255), one per ghost_ids entry; empty where 0 pixels
  std::vector<long long> mask_pixels;  // set pixels of each mask
};

// Renders a sample in the calling thread. The flare is bit for bit model.render(θ, φ, size) × scale
// (as RGB; a grey model's three channels are equal).
SampleImages renderSample(const ExportModel& model, const SampleParameters& parameters,
                          const ExportOptions& options);

// The 8-bit sRGB encoding of linear values (clipped to [0, 1], then the sRGB curve, rounded to the
// nearest code), BGR for cv::imwrite. CV_32FC3 (R, G, B) in.
cv::Mat encodeSrgb8(const cv::Mat& linear);

// A sample's line of samples.jsonl (one line, no newline) and row of samples.csv.
nlohmann::json sampleJson(const ExportModel& model, const SampleParameters& parameters,
                          const std::vector<long long>& mask_pixels, const ExportOptions& options);
std::string csvHeader();
std::string csvRow(const ExportModel& model, const SampleParameters& parameters,
                   const std::vector<long long>& mask_pixels, const ExportOptions& options);

// dataset.json: what the whole set is (the same for every shard): format, version, count, seed,
// size, options, models.
nlohmann::json datasetJson(const std::vector<ExportModel>& models, const ExportOptions& options);

struct ExportSummary {
  std::filesystem::path out_dir;
  SampleRange range;            // samples written by this run
  long long samples = 0;
  long long files = 0;          // files written
  long long bytes = 0;          // their size
  double seconds = 0;           // wall-clock time of the samples (not the loading)
  double samples_per_s = 0;
  double cpu_render_s = 0;      // CPU time over all threads: rendering and encoding in memory
  double cpu_write_s = 0;       // CPU time over all threads: compressing and writing files
  int threads = 0;
  std::filesystem::path jsonl, csv;  // this run's parameter files

  std::string BriefReport() const;
};
nlohmann::json toJson(const ExportSummary& summary);

// `flarekit export-flares`: writes the samples of options.shard into `out_dir` (created if
// missing) with dataset.json and this run's samples(.K-of-N).jsonl/.csv. Every file is written
// atomically (common/atomic_file.h). Shows progress. Throws InputError for invalid options, no
// models, or an out_dir whose dataset.json describes another set; RuntimeError on I/O failure.
ExportSummary exportFlares(const std::vector<ExportModel>& models, const ExportOptions& options,
                           const std::filesystem::path& out_dir);

}  // namespace flarekit::dataset
