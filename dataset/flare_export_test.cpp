#include <gtest/gtest.h>

#include "dataset/flare_export.h"

namespace flarekit::dataset {
namespace {

TEST(ExportOptions, DefaultsAreValid) {
  std::string why;
  EXPECT_TRUE(ExportOptions{}.IsValid(&why)) << why;
}

}  // namespace
}  // namespace flarekit::dataset
