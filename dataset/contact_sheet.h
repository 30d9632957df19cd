#pragma once
// A picture of an exported set for people: one row per sample with its compound (flare + light),
// the flare alone, the light alone and its ghosts' masks, each mask in its own colour, and a
// caption (name, model, θ, φ, EV, ghosts shown). Read back from the set's files, so it shows what
// a training loader gets.

#include <filesystem>

#include <opencv2/core.hpp>

namespace flarekit::dataset {

struct ContactSheetOptions {
  int samples = 6;          // rows: the first samples of the set's parameter file (≥ 1)
  int tile_width_px = 256;  // width of each picture in the sheet; heights keep the set's aspect (≥ 32)

  bool IsValid(std::string* error) const;
};

// The sheet of the set in `set_dir`, read through `jsonl` (samples.jsonl or a shard's
// samples.K-of-N.jsonl), as an 8-bit BGR image. Throws InputError when the files are missing.
cv::Mat contactSheet(const std::filesystem::path& set_dir, const std::filesystem::path& jsonl,
                     const ContactSheetOptions& options = {});

}  // namespace flarekit::dataset
