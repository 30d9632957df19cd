#pragma once
// The small simulated capture the capture fuzz targets work on (fuzz/README.md): a 32×24 spot
// scene, a mono sensor, three angles (0, 1, 2°), two exposures and one dark frame per exposure,
// as in acquisition/capture_test.cpp. fuzz/make_seeds writes the manifests of such captures as
// seeds, and the targets make the same capture in their scratch folder at start-up, so that a
// fuzzed manifest finds real frames, truth files and darks beside it.

#include <filesystem>

#include "acquisition/capture.h"
#include "acquisition/rig.h"

namespace flarekit::fuzz {

acquisition::Rig captureRig();
acquisition::RigDevices captureDevices(const acquisition::Rig& rig);
acquisition::CapturePlan capturePlan();

// Captures into `dir` (which must not hold a capture). stop_after_frames 0 or ≥ 2 interrupts the
// session after that many frames (status "interrupted"), as Ctrl-C would (1 acts as 0: the dark
// frames, rendered at 0°, already request the stop).
void makeSmallCapture(const std::filesystem::path& dir, int stop_after_frames = -1);

// The small capture in this process's scratch folder (scratchDir()/capture), made on first use.
const std::filesystem::path& scratchCapture();

}  // namespace flarekit::fuzz
