#pragma once
// What `flarekit metrics … --out DIR` writes (docs/metrics.md), every file atomically:
//   DIR/metrics.csv        one row per input, series (capture, truth, model) and frame: the
//                          figures of metrics/capture_metrics.h
//   DIR/ghost_flux.csv     each ghost's flux ratio over θ (with --model, and the truth's ghosts)
//   DIR/metrics.json       format "flarekit.metrics", version 1: per input its light reference,
//                          core, capture trust, notes, truth agreement, worst angles and the
//                          series' frames
//   DIR/flare_flux.png, ghost_peak.png, share_above.png, visible_ghosts.png, light.png,
//   DIR/ghost_flux.png     (with a model or truth) the figures over the rig angle θ, every input
//                          on the same axes, each input's worst angle marked and named
//   DIR/metrics.html       one page: the inputs, their light, trust, notes and the plots

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>
#include <opencv2/core.hpp>

#include "metrics/capture_metrics.h"

namespace flarekit::metrics {

// The JSON document of metrics.json.
nlohmann::json metricsJson(const std::vector<Metrics>& inputs);
// The text of metrics.csv and ghost_flux.csv.
std::string metricsCsv(const std::vector<Metrics>& inputs);
std::string ghostFluxCsv(const std::vector<Metrics>& inputs);

// The plots (8-bit BGR), by file name ("flare_flux.png", …); plots without any data are left out.
std::vector<std::pair<std::string, cv::Mat>> metricsPlots(const std::vector<Metrics>& inputs);

// Writes every file into `dir` (created). Returns the files written.
std::vector<std::filesystem::path> writeMetricsReport(const std::filesystem::path& dir,
                                                      const std::vector<Metrics>& inputs);

// One line per input for the terminal: the light, the worst angle, the trust warnings.
std::vector<std::string> briefReport(const std::vector<Metrics>& inputs);

}  // namespace flarekit::metrics
