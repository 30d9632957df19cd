#include "dataset/contact_sheet.h"

#include <gtest/gtest.h>

#include "common/error.h"
#include "common/testing.h"
#include "dataset/flare_export.h"

namespace flarekit::dataset {
namespace {

TEST(ContactSheet, ShowsOneRowOfFourPicturesPerSample) {
  testing::TempDir dir;
  ExportOptions o;
  o.count = 3;
  o.size = {64, 48};
  const ExportSummary s =
      exportFlares({ExportModel::load(std::string(FLAREKIT_SOURCE_DIR) + "/tests/data/view/nikon_model.json")}, o,
                   dir.path());
  ContactSheetOptions sheet;
  sheet.samples = 2;
  sheet.tile_width_px = 64;
  const cv::Mat two = contactSheet(dir.path(), s.jsonl, sheet);
  sheet.samples = 3;
  const cv::Mat three = contactSheet(dir.path(), s.jsonl, sheet);
  ASSERT_EQ(two.type(), CV_8UC3);
  EXPECT_GE(two.cols, 4 * 64);
  EXPECT_GT(three.rows, two.rows + 48);  // one more row of 48-pixel pictures
  EXPECT_GT(cv::norm(three, cv::NORM_L1), 0);
  EXPECT_THROW(contactSheet(dir.path(), dir / "missing.jsonl"), InputError);
  sheet.samples = 0;
  EXPECT_THROW(contactSheet(dir.path(), s.jsonl, sheet), InputError);
}

}  // namespace
}  // namespace flarekit::dataset
