// flarekit export-flares, flarekit bench export-flares: parse options, call dataset/.
#include <iostream>

#include <nlohmann/json.hpp>

#include "app/commands.h"
#include "common/config.h"
#include "common/error.h"
#include "common/log.h"
#include "common/image.h"
#include "dataset/contact_sheet.h"
#include "dataset/export_benchmark.h"
#include "dataset/flare_export.h"

namespace flarekit::app {
namespace {

// The options both commands share, filled into `o` when the command runs.
struct SetOptions {
  std::vector<std::string> models;
  std::string size = "512x512";
  double ev_min = dataset::ExportOptions{}.ev_min, ev_max = dataset::ExportOptions{}.ev_max;
  double mask_threshold = dataset::ExportOptions{}.mask_threshold;
};

void addSetOptions(CLI::App* cmd, SetOptions& s, dataset::ExportOptions& o) {
  cmd->add_option("MODEL", s.models, "Flare model files (format flarekit.flare-model); samples go to them in turn")
      ->required();
  cmd->add_option("--size", s.size, "Image size W×H (or WxH), pixels (default 512x512)");
  cmd->add_option("--seed", o.seed, "Seed of the whole set: sample i depends on (seed, i) only (default 1)");
  cmd->add_option("--ev-min", s.ev_min,
                  "Lowest exposure, stops; at EV 0 the model's white (its capture's clip level) is 1.0 (default -1)");
  cmd->add_option("--ev-max", s.ev_max, "Highest exposure, stops (default 3)");
  cmd->add_option("--mask-threshold", s.mask_threshold,
                  "A ghost's mask covers where its exposed value reaches this fraction of white (default 1/256)");
  cmd->add_flag("--light-in-frame", o.light_in_frame, "Only light positions inside the frame");
  cmd->add_option("--threads", o.threads, "Threads across samples (default: all cores)");
}

std::vector<dataset::ExportModel> loadModels(const SetOptions& s, dataset::ExportOptions& o) {
  o.size = dataset::parseSize(s.size);
  o.ev_min = s.ev_min;
  o.ev_max = s.ev_max;
  o.mask_threshold = s.mask_threshold;
  std::string why;
  if (!o.IsValid(&why)) throw InputError(why);
  std::vector<dataset::ExportModel> models;
  for (const auto& f : s.models) models.push_back(dataset::ExportModel::load(f));
  return models;
}

void registerExportFlares(CLI::App& app) {
  struct Options {
    SetOptions set;
    dataset::ExportOptions exports;
    std::string out, shard = "1/1", sheet;
    dataset::ContactSheetOptions sheet_options;
    bool json = false;
  };
  auto o = std::make_shared<Options>();
  auto* cmd = app.add_subcommand(
      "export-flares",
      "Write a flare-removal training set (Flare7K-style folders, docs/datasets.md) rendered from flare models");
  addSetOptions(cmd, o->set, o->exports);
  cmd->add_option("--count", o->exports.count, "Samples in the whole set")->required();
  cmd->add_option("--out", o->out, "Output folder (shards of one set share it)")->required();
  cmd->add_option("--shard", o->shard, "Write only part K of N of the set, K/N (default 1/1: all of it)");
  cmd->add_option("--sheet", o->sheet, "Also write a PNG contact sheet of this run's first samples");
  cmd->add_option("--sheet-samples", o->sheet_options.samples, "Samples on the sheet (default 6)");
  cmd->add_flag("--json", o->json, "Print the summary as one JSON object");
  cmd->callback([o] {
    o->exports.shard = dataset::parseShard(o->shard);
    std::string why;
    if (!o->sheet.empty() && !o->sheet_options.IsValid(&why)) throw InputError("--sheet-samples: " + why);
    const auto models = loadModels(o->set, o->exports);
    const dataset::ExportSummary s = dataset::exportFlares(models, o->exports, o->out);
    if (!o->sheet.empty()) writeImage8(o->sheet, dataset::contactSheet(o->out, s.jsonl, o->sheet_options));
    if (o->json)
      std::cout << jsonText(dataset::toJson(s)) << "\n";
    else
      logInfo(s.BriefReport());
  });
}

void registerBench(CLI::App& app) {
  struct Options {
    SetOptions set;
    dataset::ExportBenchmarkOptions bench;
    std::string scratch;
    bool json = false;
  };
  auto o = std::make_shared<Options>();
  o->bench.exports.count = 200;
  auto* cmd = benchCommand(app).add_subcommand(
      "export-flares", "Time flarekit export-flares: images per second of a whole set written to disk");
  addSetOptions(cmd, o->set, o->bench.exports);
  cmd->add_option("--count", o->bench.exports.count, "Samples (default 200)");
  cmd->add_option("--scratch", o->scratch, "Folder to write the set in (default: the system's temporary folder)");
  cmd->add_flag("--keep", o->bench.keep, "Keep the written set");
  cmd->add_flag("--json", o->json, "Print one JSON object (the default output is one line)");
  cmd->callback([o] {
    const auto models = loadModels(o->set, o->bench.exports);
    o->bench.scratch_dir = o->scratch;
    const dataset::ExportBenchmarkResult r = dataset::runExportBenchmark(models, o->bench);
    if (o->json)
      std::cout << jsonText(dataset::toJson(r)) << "\n";
    else
      std::cout << r.BriefReport() << "\n";
  });
}

}  // namespace

void registerDatasetCommands(CLI::App& app) {
  registerExportFlares(app);
  registerBench(app);
}

}  // namespace flarekit::app
