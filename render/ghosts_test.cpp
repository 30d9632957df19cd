#include "render/ghosts.h"

#include <filesystem>
#include <set>

#include <gtest/gtest.h>

namespace flarekit::render {
namespace {

Lens heliar() {
  return loadLens(std::filesystem::path(FLAREKIT_SOURCE_DIR) / "lenses" / "heliar_tronnier.json");
}

TEST(Ghosts, EverySequenceWithTwoReflectionsOnce) {
  const Lens lens = heliar();
  const auto ghosts = enumerateGhosts(lens);
  EXPECT_EQ(ghosts.size(), 28u);  // 8 interfaces: 8·7/2
  std::set<std::pair<int, int>> pairs;
  for (size_t i = 0; i < ghosts.size(); ++i) {
    const Ghost& g = ghosts[i];
    EXPECT_EQ(g.id, static_cast<int>(i));
    EXPECT_GT(g.surface_a, g.surface_b);
    EXPECT_FALSE(lens.surfaces[static_cast<size_t>(g.surface_a)].is_stop);
    EXPECT_FALSE(lens.surfaces[static_cast<size_t>(g.surface_b)].is_stop);
    pairs.insert({g.surface_a, g.surface_b});
  }
  EXPECT_EQ(pairs.size(), ghosts.size());
}

TEST(Ghosts, PathsReflectTwiceAndEndForwardAtTheLastSurface) {
  const Lens lens = heliar();
  for (const Ghost& g : enumerateGhosts(lens)) {
    const auto path = ghostPath(lens, g.surface_a, g.surface_b);
    int reflections = 0, stops = 0;
    for (const PathEvent& e : path) {
      reflections += e.kind == EventKind::kReflect;
      stops += e.kind == EventKind::kStop;
    }
    EXPECT_EQ(reflections, 2);
    // Same-side ghosts cross the stop once, the others three times.
    EXPECT_EQ(stops, g.same_side_of_stop ? 1 : 3) << g.surface_a << "," << g.surface_b;
    EXPECT_EQ(path.back().surface, static_cast<int>(lens.surfaces.size()) - 1);
    EXPECT_TRUE(path.back().forward);
    EXPECT_EQ(path.size(), lens.surfaces.size() + 2 * static_cast<size_t>(g.surface_a - g.surface_b));
  }
  const auto direct = directPath(lens);
  EXPECT_EQ(direct.size(), lens.surfaces.size());
}

}  // namespace
}  // namespace flarekit::render
