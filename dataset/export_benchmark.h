#pragma once
// The measurement behind `flarekit bench export-flares` (issue 59's target: at least 20 images per
// second at 512×512 on 2 cores): a whole export (every file of every sample, written atomically)
// into a fresh folder, timed from the first sample to the last file.

#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "dataset/flare_export.h"

namespace flarekit::dataset {

struct ExportBenchmarkOptions {
  ExportOptions exports;             // count, size, seed, threads ... (shard ignored: a whole set)
  // Where the set is written: a new folder made under it and removed afterwards (default: the
  // system's temporary folder). The disk matters: every file is flushed to it.
  std::filesystem::path scratch_dir;
  bool keep = false;                 // keep the written set (its folder is in the result)

  bool IsValid(std::string* error) const;
};

struct ExportBenchmarkResult {
  std::vector<std::string> models;
  int width = 0, height = 0, threads = 0;
  long long samples = 0, files = 0, bytes = 0;
  double seconds = 0;                // wall-clock time of the export (models loaded before)
  double samples_per_s = 0;          // the figure of the target ("images per second")
  double cpu_s = 0;                  // CPU time of the whole process during the export
  // cpu_s per sample: on N idle cores the export approaches N · 1000 / cpu_ms_per_sample samples
  // per second, whatever else loaded the machine while it was measured.
  double cpu_ms_per_sample = 0;
  double ms_render_per_sample = 0;   // CPU time per sample: rendering and encoding in memory
  double ms_write_per_sample = 0;    // CPU time per sample: compressing and writing its files
  std::filesystem::path folder;      // where the set was written (removed unless kept)

  std::string BriefReport() const;
};

ExportBenchmarkResult runExportBenchmark(const std::vector<ExportModel>& models,
                                         const ExportBenchmarkOptions& options);
nlohmann::json toJson(const ExportBenchmarkResult& result);

}  // namespace flarekit::dataset
