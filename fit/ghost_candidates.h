#pragma once
// Stage 4 of the fit (docs/fitting.md): ghosts from the border traces of the sweep image.
//
// A ghost is bounded on the horizon by a rising trace (its left border) and a falling one (its
// right border). The model gives one outline value Ib to the whole outline, so both borders of one
// ghost step by about the same amount in S (linear, where overlapping ghosts add): rising and
// falling traces are paired by that step, left of right over the frames they share; and a ghost
// keeps its size as it moves (paraxially exactly), so the two borders of a pair move alike. The
// closest pair (steps, and the change of the distance between the borders) first, each trace in
// one pair. Nested and overlapping ghosts give separate pairs. A pair's middle must be, as a real
// ghost's, an odd function about the optical zero (fit/horizon.h): pairs of two unrelated borders,
// or of a border and a rim's inner edge, are centred elsewhere.
//
// A trace that keeps its distance to the light while the light moves is the edge of the light's
// own image (its glow, a starburst spike), never a ghost's: only a ghost focused on the sensor
// moves with the light, and it is drawn on the light's core.
//
// A peak of S (sweep.h) is a ghost of its own, centred on it, unless it is the middle of a paired
// ghost or runs along a border (a bright rim just inside it): a ghost too small for the sweep
// to resolve its borders, or one whose light gathers to a point with no sharp border.
//
// A trace left over is a ghost whose other border is hidden (beyond the frame, or in the light's
// zone) when S stays raised from the trace to there on the ghost's side, all the way (a large
// ghost at some angles, a ghost about the light), except where the light's own profile outshines
// it (that profile, measured over the frames, holds a ghost that stays beside the light);
// otherwise it is an edge inside a ghost (a caustic's rim or fold) and no ghost of its own.
//
// Each ghost gets its angle range (its traces' frames, and on while its borders are hidden in the
// light's zone or beyond the frame) and, at every frame in it, a seed: Mx, L,
// R from its borders, where a border is not traced from its border model (its middle an odd
// function of the light's offset from the optical axis, its half-width an even one, fitted to all
// the points of its traces), h from the vertical profile of
// the frame through Mx (where it falls by the borders' step), Ib from the step, Ii from S in the
// middle.

#include <string>
#include <vector>

#include "fit/frames.h"
#include "fit/sweep.h"
#include "model/ghost_shape.h"

namespace flarekit::fit {

struct CandidateOptions {
  int min_shared_rows = 3;          // a pair's traces share at least this many frames (≥ 1)
  double max_step_ratio = 2.5;      // their steps differ by at most this factor (> 1)
  double max_width_change_per_deg = 0.15;  // their distance changes by at most this fraction a degree
  double max_centre_rms_px = 2;     // their middle's distance from an odd curve about the zero
  double min_motion_from_light = 0.05;  // a border moves, relative to the light, at least this
                                        // fraction of the light's own motion (≥ 0)
  double single_significance = 20;  // a lone trace's significance to stand for a ghost (> 0)
  double single_raised_sigma = 3;   // S stays raised above the outside by this many noise σ (≥ 0)
  double single_raised_fraction = 0.5;  // and nowhere by less than this fraction of its step (or
                                        // of its typical rise, where a rim makes that the less)
  int max_hidden_rows = 30;         // a ghost goes on this many frames beyond its traces when hidden
  int profile_half_columns = 2;     // columns averaged on each side of Mx for h (≥ 0)
  double min_height_fraction = 0.3; // h is searched within [this, 1/this] × the half-width
  double seed_outside_falloff_px = 2;  // Fo of the seeds, pixels (> 0)
  double rim_px = 4;                // a peak this close to a border, most of its frames, is a rim
  int peak_reach_px = 60;           // a peak's half level is looked for within this distance (≥ 1)

  bool IsValid(std::string* error) const;
};

struct GhostCandidate {
  int id = 0;
  int left_trace = -1, right_trace = -1;  // BorderTrace ids; −1 where that border is never seen
  int peak_trace = -1;                    // the BorderSide::kPeak trace it is centred on, or −1
  int first_row = 0, last_row = 0;        // sweep rows (the stack's frames) it is present in
  std::vector<model::GhostParameters> seeds;  // one per row first_row..last_row
  std::vector<bool> left_seen, right_seen;    // per row: the sweep traced that border there, in the frame
  double step = 0;                        // median step of its borders in S (linear radiance)

  bool present(int row) const { return row >= first_row && row <= last_row; }
  const model::GhostParameters& seed(int row) const { return seeds[row - first_row]; }
  bool leftSeen(int row) const { return left_seen[row - first_row]; }
  bool rightSeen(int row) const { return right_seen[row - first_row]; }
};

struct CandidateSummary {
  int pairs = 0;          // ghosts with both borders seen
  int single = 0;         // ghosts from one border
  int peaks = 0;          // ghosts from a peak
  int traces_unused = 0;  // traces that are none of these (inner edges, rims, a pair's middle)
};

// The ghosts of the capture from its traces. `stack` gives the frames for the vertical profiles,
// `horizon_y_px` the mirror axis My of every seed.
std::vector<GhostCandidate> findGhostCandidates(const FrameStack& stack, const SweepImage& sweep,
                                                const std::vector<BorderTrace>& traces,
                                                const CandidateOptions& options = {},
                                                CandidateSummary* summary = nullptr);

// Each candidate's centre samples where both its borders are seen, or its peak: for
// measureOpticalZero.
std::vector<CentreSamples> centreSamples(const std::vector<GhostCandidate>& candidates,
                                         const std::vector<BorderTrace>& traces,
                                         const SweepImage& sweep);

}  // namespace flarekit::fit
