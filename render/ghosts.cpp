#include "render/ghosts.h"

namespace flarekit::render {

std::vector<Ghost> enumerateGhosts(const Lens& lens) {
  const std::vector<int> interfaces = lens.interfaceIndices();
  const int stop = lens.stopIndex();
  std::vector<Ghost> ghosts;
  int id = 0;
  for (size_t ia = 1; ia < interfaces.size(); ++ia)
    for (size_t ib = 0; ib < ia; ++ib) {
      Ghost g;
      g.id = id++;
      g.surface_a = interfaces[ia];
      g.surface_b = interfaces[ib];
      g.same_side_of_stop = (g.surface_a < stop) == (g.surface_b < stop);
      ghosts.push_back(g);
    }
  return ghosts;
}

std::vector<PathEvent> ghostPath(const Lens& lens, int a, int b) {
  const int n = static_cast<int>(lens.surfaces.size());
  std::vector<PathEvent> path;
  auto add = [&](int surface, bool forward, bool reflect) {
    PathEvent e;
    e.surface = surface;
    e.forward = forward;
    // Forward, the ray is in the medium before the surface (index surface − 1) and enters the
    // one after it (index surface); backward the other way round.
    e.medium_before = forward ? surface - 1 : surface;
    e.medium_after = reflect ? e.medium_before : (forward ? surface : surface - 1);
    e.n_before = lens.refractiveIndex(e.medium_before, kWavelengthD_nm);
    e.kind = lens.surfaces[static_cast<size_t>(surface)].is_stop
                 ? EventKind::kStop
                 : (reflect ? EventKind::kReflect : EventKind::kRefract);
    path.push_back(e);
  };
  if (a < 0) {
    for (int i = 0; i < n; ++i) add(i, true, false);
    return path;
  }
  for (int i = 0; i < a; ++i) add(i, true, false);
  add(a, true, true);
  for (int i = a - 1; i > b; --i) add(i, false, false);
  add(b, false, true);
  for (int i = b + 1; i < n; ++i) add(i, true, false);
  return path;
}

}  // namespace flarekit::render
