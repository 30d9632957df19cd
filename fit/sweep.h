#pragma once
// Stage 3 of the fit (docs/fitting.md): the sweep image and the ghosts' border traces in it.
//
// The sweep image S(θ, x) stacks the horizon rows of all frames over θ (a band of rows about the
// horizon, the rows mirrored about it averaged: every ghost is symmetric about it). The horizon
// holds every ghost's left and right extreme points, so each ghost draws a band between two
// smooth curves x_L(θ) and x_R(θ), and the light draws its own curve. Borders too faint to see in
// any one frame are plain lines here, because they continue over many frames.
//
// The light's own profile along the horizon is the same in every frame that shows it, moved with
// the light: its percentile over those frames, at each distance from the light's centre, is taken
// out of S, so that its halo and the fringes of its starburst draw no borders; its zone, its
// core on the horizon (clipped, or above half its peak where a merged frame holds it unclipped),
// is masked.
//
// Borders are edges along x: the derivative of Gaussian of log S less its running median over
// ±2 trend_sigma_px (the smooth slope under the borders, which is no border), in σ of its noise
// (from a shot + read noise model measured on the mirrored rows' differences). A left
// border rises, a right border falls. Peaks are where that derivative (without the trend taken
// out) falls through 0, as strong as the curvature there in σ: a peak is no border, so the
// borders' rising and falling flanks need not be resolved to find it. Trace points are the local extrema beyond peak_sigma; they
// are linked over θ by their predicted position (a line through the trace's last points), split
// where their slope kinks (the linking passed onto a crossing border), the light's fringes (which
// keep their distance from it) left out, and the pieces of one border that the light or a
// crossing border interrupted are joined where one low-degree polynomial runs through both.

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "fit/frames.h"
#include "fit/horizon.h"
#include "model/flare_model.h"

namespace flarekit::fit {

struct SweepOptions {
  int band_half_rows = 3;           // rows averaged on each side of the horizon (≥ 0)
  double edge_sigma_px = 1.2;       // Gaussian of the derivative along x, pixels (> 0)
  double trend_sigma_px = 6;        // slopes smoother than this are no border (> edge_sigma_px)
  double light_window_px = 160;     // the light's profile is taken out within this distance (≥ 0)
  double light_percentile = 0.2;    // its profile: this quantile over the frames showing it (0, 1)
  int light_min_frames = 5;         // and over at least this many of them; fewer: none (≥ 1)
  double peak_sigma = 3;            // trace points beyond this many noise σ (edge, curvature) (> 0)
  double gate_px = 1.5;             // a trace's next point lies this close to its prediction (> 0)
  double max_slope_px = 20;         // a new trace moves at most this many px per frame (> 0)
  int max_gap_rows = 4;             // a trace goes on after this many frames without a point
  int min_trace_rows = 5;           // shorter traces are dropped (≥ 2)
  double min_significance = 10;     // a trace's Σ strength / √points, noise σ (> 0)
  int kink_rows = 5;                // a trace's slope is taken over this many frames (≥ 2)
  double max_kink_px_per_row = 1;   // and split where it changes by more than this (> 0)
  int max_join_gap_rows = 25;       // pieces of one border this many frames apart are joined
  double join_tolerance_px = 2;     // if one polynomial runs within this of both (RMS: half)

  bool IsValid(std::string* error) const;
};

struct SweepImage {
  std::vector<double> angles_deg;  // one per row, ascending (the stack's frames)
  double horizon_y_px = 0;
  cv::Mat radiance;                // CV_32F rows × width: the horizon band's luminance
  cv::Mat light;                   // CV_32F: the light's own profile taken out of it
  cv::Mat valid;                   // CV_8U: 255 where the edge response means something
  cv::Mat noise;                   // CV_32F: noise σ of `radiance` at each point
  cv::Mat edge;                    // CV_32F: border response of log(radiance − light), in σ
  cv::Mat slope;                   // CV_32F: derivative of Gaussian of log(radiance − light), per px
  cv::Mat peak;                    // CV_32F: its curvature (negative second derivative), in σ
  std::vector<double> light_x_px;  // the light's centre per row (NaN outside the frame)
  double light_zone_left_px = 0;   // the light's zone reaches this far to its left and right
  double light_zone_right_px = 0;

  // Whether x lies in the light's zone at `row` (where no border is traced).
  bool inLightZone(int row, double x) const {
    const double d = x - light_x_px[row];
    return d > -light_zone_left_px && d < light_zone_right_px;  // false where the light is absent
  }

  int rows() const { return radiance.rows; }
  int width() const { return radiance.cols; }
};

enum class BorderSide {
  kLeft,   // rising along x: the ghost lies to its right
  kRight,  // falling along x: the ghost lies to its left
  kPeak,   // S peaks along x there: a ghost too narrow for its borders to be told apart, or a
           // ghost whose light gathers to a point (near focus) with no sharp border of its own
};

struct BorderPoint {
  int row = 0;          // frame index in the sweep
  double x_px = 0;      // sub-pixel position of the extremum
  double strength = 0;  // |edge response|, noise σ
  double jump = 0;      // S just inside minus just outside the border (linear, > 0 for a ghost);
                        // at a peak, S − light there
};

struct BorderTrace {
  int id = 0;
  BorderSide side = BorderSide::kLeft;
  std::vector<BorderPoint> points;  // ascending rows, at most one per row
  model::Polynomial x_of_angle;    // x(θ), θ in degrees, least squares through the points
  double significance = 0;         // Σ strength / √points

  int firstRow() const { return points.front().row; }
  int lastRow() const { return points.back().row; }
  // The point at `row`, or nullptr.
  const BorderPoint* at(int row) const;
};

// Builds S from the stack (luminance, the band about horizon.y_px), with the light's profile
// taken out along the light's centres in `horizon`.
SweepImage buildSweep(const FrameStack& stack, const Horizon& horizon,
                      const SweepOptions& options = {});

// The border traces of S, significant ones only, ids from 0.
std::vector<BorderTrace> findTraces(const SweepImage& sweep, const SweepOptions& options = {});

}  // namespace flarekit::fit
