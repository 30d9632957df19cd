// The real libusb code path of TicHead against a behavioural model of a Pololu Tic behind a
// umockdev USB device (acquisition/testing/tic_emulator.h).
#include "acquisition/tic_head.h"

#include <gtest/gtest.h>

#include <mutex>
#include <string>

#include "acquisition/testing/tic_emulator.h"

namespace flarekit::acquisition {
namespace {

class TicBench : public ::testing::Test {
 protected:
  void plugIn() { ASSERT_TRUE(emulated_.plugIn()); }
  static TicConfig config() {
    TicConfig c;
    c.geometry.full_steps_per_rev = 200;
    c.geometry.microsteps = 8;
    c.geometry.gear_ratio = 1;  // 4.44 microsteps per degree: 0.225° per microstep
    c.geometry.backlash_deg = 0.9;
    c.geometry.min_deg = -90;
    c.geometry.max_deg = 90;
    c.move_timeout_s = 2;
    return c;
  }

  testing::EmulatedTic emulated_;
  testing::TicModel& tic = emulated_.model();
};

TEST_F(TicBench, MovesToTargetsFromOneSideAndReportsPositions) {
  plugIn();
  TicHead head(config(), "tic-test.toml");
  EXPECT_NE(head.describe().find("00314159"), std::string::npos) << head.describe();
  head.home();
  EXPECT_EQ(head.readPosition(), 0);
  head.moveTo(45);  // 200 microsteps
  EXPECT_EQ(head.readPosition(), 200);
  EXPECT_DOUBLE_EQ(head.angleDeg(), 45);
  head.moveTo(22.5);  // backwards: overshoot by 4 microsteps of backlash, come back
  EXPECT_EQ(head.readPosition(), 100);
  std::lock_guard<std::mutex> lock(tic.mutex);
  EXPECT_TRUE(tic.energized);
  EXPECT_FALSE(tic.safe_start);
  EXPECT_EQ(tic.targets_set, 3);  // 200, then 96 (overshoot) and 100
  EXPECT_GT(tic.timeout_resets, 5);  // command timeout reset while waiting
  // Speed 10°/s × 4.44 microsteps/° × 10⁴, acceleration 20°/s² × 4.44 × 100.
  EXPECT_EQ(tic.max_speed, 444444);
  EXPECT_EQ(tic.max_accel, 8889);
}

TEST_F(TicBench, RejectsAnglesThatAreNotWholeMicrosteps) {
  plugIn();
  TicHead head(config(), "tic-test.toml");
  head.home();
  try {
    head.moveTo(0.2);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("0.225"), std::string::npos) << e.what();
  }
}

TEST_F(TicBench, ControllerErrorsBecomeClearMessages) {
  plugIn();
  TicHead head(config(), "tic-test.toml");
  head.home();
  {
    std::lock_guard<std::mutex> lock(tic.mutex);
    tic.fail_after_reads = tic.reads + 2;
  }
  try {
    head.moveTo(90);
    FAIL();
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("motor driver error"), std::string::npos) << e.what();
    EXPECT_FALSE(e.transient());
  }
}

TEST_F(TicBench, StallTimesOutWithAClearError) {
  plugIn();
  TicConfig c = config();
  c.move_timeout_s = 0.3;
  TicHead head(c, "tic-test.toml");
  head.home();
  {
    std::lock_guard<std::mutex> lock(tic.mutex);
    tic.stall = true;
  }
  try {
    head.moveTo(10 * 0.225);
    FAIL();
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("stalled"), std::string::npos) << e.what();
  }
}

TEST_F(TicBench, MissingControllerSaysWhatToCheck) {
  try {
    TicHead head(config(), "tic-test.toml");
    FAIL();
  } catch (const DeviceError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("no Pololu Tic"), std::string::npos) << m;
    EXPECT_NE(m.find("tic-test.toml"), std::string::npos) << m;
  }
  std::vector<std::string> lines;
  EXPECT_FALSE(probeTic(config(), &lines));
}

TEST_F(TicBench, WrongSerialIsNotUsed) {
  plugIn();
  TicConfig c = config();
  c.serial = "99999999";
  EXPECT_THROW(TicHead head(c, "tic-test.toml"), DeviceError);
  std::vector<std::string> lines;
  c.serial = "00314159";
  EXPECT_TRUE(probeTic(c, &lines));
}

}  // namespace
}  // namespace flarekit::acquisition
