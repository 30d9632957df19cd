#include "common/progress.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <sstream>

#include "common/log.h"

namespace flarekit {
namespace {

struct LevelGuard {
  LogLevel saved = logLevel();
  ~LevelGuard() { setLogLevel(saved); }
};

TEST(Progress, PipeGetsAtMostALinePerTenPercent) {
  LevelGuard guard;
  setLogLevel(LogLevel::kInfo);
  std::ostringstream out;
  {
    Progress p("fitting", 1000, out, false);
    for (int i = 0; i < 1000; ++i) p.advance();
  }
  std::string s = out.str();
  long lines = std::count(s.begin(), s.end(), '\n');
  EXPECT_GE(lines, 2);
  EXPECT_LE(lines, 10);  // 10 %, 20 %, ... 90 % and the final line
  EXPECT_NE(s.find("1000/1000"), std::string::npos) << s;
  EXPECT_EQ(s.find('\r'), std::string::npos);
}

TEST(Progress, TerminalGetsABarWithRateAndEta) {
  LevelGuard guard;
  setLogLevel(LogLevel::kInfo);
  std::ostringstream out;
  Progress p("capture", 4, out, true);
  p.advance();
  std::string s = out.str();
  EXPECT_NE(s.find('\r'), std::string::npos);
  EXPECT_NE(s.find("1/4"), std::string::npos);
  EXPECT_NE(s.find("/s"), std::string::npos);
  EXPECT_NE(s.find("ETA"), std::string::npos);
  p.finish();
  EXPECT_NE(out.str().find("took"), std::string::npos);
}

TEST(Progress, QuietPrintsNothing) {
  LevelGuard guard;
  setLogLevel(LogLevel::kWarning);
  std::ostringstream out;
  {
    Progress p("x", 10, out, true);
    for (int i = 0; i < 10; ++i) p.advance();
  }
  EXPECT_TRUE(out.str().empty());
}

TEST(Progress, FormatsDurations) {
  EXPECT_EQ(formatDuration(1.5), "1.5 s");
  EXPECT_EQ(formatDuration(123), "2 min 03 s");
  EXPECT_EQ(formatDuration(3720), "1 h 02 min");
}

}  // namespace
}  // namespace flarekit
