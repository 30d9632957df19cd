#include "dataset/export_benchmark.h"

#include <ctime>
#include <random>
#include <sstream>

#include <nlohmann/json.hpp>

#include "common/error.h"

namespace flarekit::dataset {
namespace {

double processCpuS() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + t.tv_nsec / 1e9;
}

}  // namespace

bool ExportBenchmarkOptions::IsValid(std::string* error) const {
  ExportOptions whole = exports;
  whole.shard = {};
  return whole.IsValid(error);
}

ExportBenchmarkResult runExportBenchmark(const std::vector<ExportModel>& models, const ExportBenchmarkOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) throw InputError("bench export-flares: " + why);
  ExportOptions options = o.exports;
  options.shard = {};
  const std::filesystem::path parent = o.scratch_dir.empty() ? std::filesystem::temp_directory_path() : o.scratch_dir;
  const std::filesystem::path folder =
      parent / ("flarekit-bench-export-" + std::to_string(std::random_device{}()));

  ExportBenchmarkResult r;
  const double cpu0 = processCpuS();
  ExportSummary s;
  try {
    s = exportFlares(models, options, folder);
  } catch (...) {
    std::error_code ec;
    if (!o.keep) std::filesystem::remove_all(folder, ec);
    throw;
  }
  r.cpu_s = processCpuS() - cpu0;
  for (const auto& m : models) r.models.push_back(m.file);
  r.width = options.size.width;
  r.height = options.size.height;
  r.threads = s.threads;
  r.samples = s.samples;
  r.files = s.files;
  r.bytes = s.bytes;
  r.seconds = s.seconds;
  r.samples_per_s = s.samples_per_s;
  r.cpu_ms_per_sample = s.samples ? 1e3 * r.cpu_s / s.samples : 0;
  r.ms_render_per_sample = s.samples ? 1e3 * s.cpu_render_s / s.samples : 0;
  r.ms_write_per_sample = s.samples ? 1e3 * s.cpu_write_s / s.samples : 0;
  r.folder = folder;
  if (!o.keep) {
    std::error_code ec;
    std::filesystem::remove_all(folder, ec);
  }
  return r;
}

std::string ExportBenchmarkResult::BriefReport() const {
  std::ostringstream s;
  s.precision(3);
  s << samples << " samples at " << width << "x" << height << " on " << threads << " threads: " << samples_per_s
    << " images/s (" << seconds << " s; per sample " << ms_render_per_sample << " ms rendering, "
    << ms_write_per_sample << " ms writing " << (samples ? files / samples : 0) << " files; CPU " << cpu_ms_per_sample
    << " ms per sample)";
  return s.str();
}

nlohmann::json toJson(const ExportBenchmarkResult& r) {
  return {{"benchmark", "export-flares"},
          {"models", r.models},
          {"width", r.width},
          {"height", r.height},
          {"threads", r.threads},
          {"samples", r.samples},
          {"files", r.files},
          {"bytes", r.bytes},
          {"seconds", r.seconds},
          {"samples_per_s", r.samples_per_s},
          {"cpu_s", r.cpu_s},
          {"cpu_ms_per_sample", r.cpu_ms_per_sample},
          {"ms_render_per_sample", r.ms_render_per_sample},
          {"ms_write_per_sample", r.ms_write_per_sample},
          {"folder", r.folder.string()}};
}

}  // namespace flarekit::dataset
