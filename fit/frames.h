#pragma once
// The input of the fitter: a stack of HDR frames over rig angles (Walch et al. 2018 §3.1), either
// a capture folder written by the acquisition layer (manifest.json "flarekit.capture" v1, see the
// layout at the top of acquisition/capture.h; parsed here with common/config.h so that fit/ does
// not depend on acquisition/) or a plain "EXR stack" from another system: a folder of EXR files or
// a list of them, each frame's angle from its flarekit.angle_deg attribute, from a CSV file, or
// from its file name.
//
// Every problem with the input is an InputError naming the file and what is wrong: missing or
// unreadable frames, repeated or missing angles, frames of different sizes or channel layouts,
// an inconsistent manifest. All-black frames are left out with one warning each (a capture that is
// black throughout is an error): they carry no information and would pull every ghost to zero.

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "model/flare_model.h"

namespace flarekit::fit {

// Two rig angles this close are the same frame's (repeated angles in a stack, a frame looked up by
// its angle, figures of one capture joined by angle).
inline constexpr double kAngleToleranceDeg = 1e-6;

// One frame of the stack, in memory.
struct Frame {
  int index = 0;                      // position in the capture plan (or in the stack's file order)
  double angle_deg = 0;               // rig angle θ
  std::filesystem::path file;         // the frame's EXR file
  cv::Mat image;                      // CV_32FC1 or CV_32FC3 linear radiance; non-finite set to 0
  cv::Mat valid;                      // CV_8U: 255 where the pixel is finite and not saturated
  std::filesystem::path truth_file;   // noise-free radiance (simulated captures), else empty
  std::filesystem::path ghosts_file;  // per-ghost ground truth layers ("ghost.<id>.*": a file of its
                                      // own, or the truth file itself), else empty
};

struct FrameStack {
  std::vector<Frame> frames;          // sorted by angle, all-black frames left out
  int channels = 1;                   // 1 (Y or a named one-channel layer) or 3 (R, G, B)
  cv::Size size;                      // every frame's size
  model::CaptureInfo info;            // camera, lens, light, exposure as far as known
  bool has_truth = false;             // every frame has truth_file and ghosts_file
  std::filesystem::path source;       // the capture folder, or the first file of a stack
  std::vector<std::string> warnings;  // one line per frame left out or per oddity

  // The index in `frames` of the frame at angle θ (within kAngleToleranceDeg), or -1.
  int findAngle(double angle_deg) const;
  // The median step between successive frames' angles, degrees (1 with fewer than two frames).
  double medianStepDeg() const;
};

struct FrameLoadOptions {
  // Layer holding the image: "" = the main layer (Y or R,G,B), else a named layer ("beauty",
  // "ghost.3", ...; one channel or .R/.G/.B).
  std::string layer;
  // EXR stacks only: a CSV file "file,angle_deg" (header line optional; file names relative to the
  // CSV's folder or bare names). Empty: use the attribute or the pattern.
  std::filesystem::path angles_csv;
  // EXR stacks only: an ECMAScript regular expression searched in the file name (without folder)
  // whose first capture group is the angle in degrees, e.g. "theta_([-0-9.]+)". Empty: unused.
  std::string angle_pattern;
  // EXR stacks only: capture metadata that the files do not carry (the model file stores it).
  // Fields left at 0 / empty are filled from attributes where present, else with 1 / "unknown".
  model::CaptureInfo info;
  // A frame counts as all-black when its largest finite value is ≤ this (linear radiance).
  double black_threshold = 0;

  bool IsValid(std::string* error) const;
};

// A capture folder (manifest.json inside). Frames are read in full.
FrameStack loadCapture(const std::filesystem::path& folder, const FrameLoadOptions& options = {});

// An EXR stack: `inputs` are EXR files or folders (all *.exr files inside, not recursive).
FrameStack loadExrStack(const std::vector<std::filesystem::path>& inputs,
                        const FrameLoadOptions& options = {});

// What the command line takes: one folder with manifest.json → loadCapture, else loadExrStack.
FrameStack loadFrames(const std::vector<std::filesystem::path>& inputs,
                      const FrameLoadOptions& options = {});

// Reads one frame image and its mask from an EXR file (the main layer or `layer`, plus the
// "saturated" layer when present). Throws InputError for missing layers or bad files.
void readFrameImage(const std::filesystem::path& file, const std::string& layer, cv::Mat& image,
                    cv::Mat& valid);

// The sum of the per-ghost truth layers of a frame ("ghost.<id>.*"), with each ghost's image:
// the noise-free flare that fit-eval compares the model with.
struct GhostTruth {
  int id = 0;
  cv::Mat image;  // CV_32FC(channels)
};
std::vector<GhostTruth> readGhostTruth(const std::filesystem::path& ghosts_file);

}  // namespace flarekit::fit
