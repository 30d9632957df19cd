#pragma once
// Ghost enumeration (Hullin 2011 §3, Bodonyi & Kunkli 2023 §3.1): every light path with exactly
// two reflections — forward to interface a, back to interface b < a, forward to the sensor —
// n(n−1)/2 paths for n refracting interfaces (the stop reflects nothing). Each path is a fixed
// sequence of surface events that the tracer and the paraxial matrices walk in order.

#include <vector>

#include "render/lens.h"

namespace flarekit::render {

enum class EventKind {
  kRefract,  // refraction through the interface (transmission 1 − R)
  kReflect,  // reflection at the interface (reflectance R)
  kStop,     // passing the aperture stop plane (records aperture coordinates)
};

// One step of a path: the ray reaches `surface` travelling towards +z (`forward`) or −z.
struct PathEvent {
  int surface = 0;
  EventKind kind = EventKind::kRefract;
  bool forward = true;    // direction of travel before the event
  double n_before = 1.0;  // index of the medium the ray is in before the event (at the d line;
                          // the tracer re-evaluates indices per wavelength through the surfaces)
  int medium_before = -1; // Lens::refractiveIndex index of that medium
  int medium_after = -1;  // ... and of the medium after the event (same for reflections)
};

struct Ghost {
  // Stable id: position in the enumeration over all pairs, ordered by a then b (a = 1..n−1 over
  // interfaces, b = 0..a−1); the same lens always gives the same ids, whatever is culled.
  int id = 0;
  int surface_a = 0;  // first reflection (later surface), index into Lens::surfaces
  int surface_b = 0;  // second reflection (earlier surface)
  bool same_side_of_stop = false;  // both reflections before, or both after, the stop
  double intensity_estimate = 0.0; // filled by rankGhosts
};

// Every two-reflection ghost of the lens, by id.
std::vector<Ghost> enumerateGhosts(const Lens& lens);

// The event sequence of a ghost (a ≥ 0, b ≥ 0), or of the direct path (a = b = −1).
std::vector<PathEvent> ghostPath(const Lens& lens, int surface_a, int surface_b);
inline std::vector<PathEvent> directPath(const Lens& lens) { return ghostPath(lens, -1, -1); }

}  // namespace flarekit::render
