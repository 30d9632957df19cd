// HDR merge accuracy on simulated brackets with a known noise model.
#include "acquisition/hdr_merge.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

namespace flarekit::acquisition {
namespace {

// Sensor used by these tests: 14-bit, black 512, 4 e-/DN, read noise 3 e-, 1000 e-/s per unit.
constexpr double kBlack = 512, kWhite = 16383, kGain = 4.0, kRead = 3.0, kScale = 1000.0;

// Test-local sensor (EMVA 1288 model: Poisson electrons, Gaussian read noise, clipping).
RawFrame expose(const cv::Mat& radiance, double t, std::mt19937_64& rng, Cfa cfa = Cfa::kMono) {
  RawFrame f;
  f.data.create(radiance.size(), CV_16UC1);
  std::normal_distribution<double> read(0, kRead / kGain);
  for (int y = 0; y < radiance.rows; ++y)
    for (int x = 0; x < radiance.cols; ++x) {
      const double mean_e = radiance.at<float>(y, x) * kScale * t;
      std::poisson_distribution<long long> shot(std::max(mean_e, 1e-9));
      const double e = mean_e > 1e9 ? mean_e : static_cast<double>(shot(rng));
      const double dn = std::round(e / kGain + read(rng) + kBlack);
      f.data.at<uint16_t>(y, x) = static_cast<uint16_t>(std::clamp(dn, 0.0, kWhite));
    }
  f.cfa = cfa;
  f.black_level = kBlack;
  f.white_level = kWhite;
  f.exposure_s = t;
  return f;
}

MergeOptions testOptions() {
  MergeOptions o;
  o.gain_e_per_dn = kGain;
  o.read_noise_e = kRead;
  o.output_scale = kScale;
  return o;
}

// Radiance: a log ramp over 6 decades (1e-3 .. 1e3) in 256 columns, plus a 20×20 spot at 1e5
// that saturates every exposure.
cv::Mat testScene() {
  cv::Mat r(300, 256, CV_32FC1);
  for (int y = 0; y < r.rows; ++y)
    for (int x = 0; x < r.cols; ++x)
      r.at<float>(y, x) = static_cast<float>(std::pow(10.0, -3.0 + 6.0 * x / (r.cols - 1)));
  r(cv::Rect(100, 250, 20, 20)).setTo(1e5f);
  return r;
}

TEST(MergeOptions, DefaultsAreValid) {
  std::string error;
  EXPECT_TRUE(MergeOptions{}.IsValid(&error)) << error;
  MergeOptions bad;
  bad.saturation_fraction = 1.5;
  EXPECT_FALSE(bad.IsValid(&error));
  EXPECT_NE(error.find("saturation_fraction"), std::string::npos);
}

// Over six decades of radiance the merge reaches the noise limit of the bracket: errors
// normalised by the predicted σ of the optimal estimate follow a unit normal (median 0.674,
// p99 2.576) within 10 %. (The "≤ 1 % median, ≤ 5 % p99 over SNR ≥ 10" cannot hold on a
// ramp where many photosites sit near SNR 10, whose own noise is 10 %; it is checked on a
// rendered flare frame in tests/cli_acquisition_test.cpp. The relative errors are printed.)
TEST(HdrMerge, NoiseOptimalOverSixDecadesAndFlagsSaturation) {
  const cv::Mat truth = testScene();
  double lo, hi;
  cv::minMaxLoc(truth, &lo, &hi);
  ASSERT_GE(hi / lo, 1e5);
  const std::vector<double> times = {0.25, 1, 4};
  std::mt19937_64 rng(42);
  std::vector<RawFrame> frames;
  for (double t : times) frames.push_back(expose(truth, t, rng));
  MergeResult m = mergeBracket(frames, testOptions());
  ASSERT_EQ(m.merged.size(), truth.size());

  const double sat_e = 0.95 * (kWhite - kBlack) * kGain;  // electrons at the saturation threshold
  std::vector<double> errors, normalised;
  int flagged_ok = 0, must_flag = 0;
  double lo_used = 1e30, hi_used = 0;
  for (int y = 0; y < truth.rows; ++y)
    for (int x = 0; x < truth.cols; ++x) {
      const double r = truth.at<float>(y, x);
      const double est = m.merged.at<float>(y, x);
      const bool flagged = m.saturated.at<uint8_t>(y, x) != 0;
      // Expected noise of each exposure; predicted SNR of the optimal merge.
      double inv_var = 0, sigma_shortest = -1;
      for (double t : times) {
        const double e = r * kScale * t;
        if (e >= sat_e * 0.98) continue;
        const double var = (e + kRead * kRead) / (kScale * t) / (kScale * t);
        inv_var += 1 / var;
        if (sigma_shortest < 0) sigma_shortest = std::sqrt(var);
      }
      if (inv_var == 0) {
        if (r * kScale * times[0] > sat_e * 1.05) {
          ++must_flag;
          flagged_ok += flagged;
        }
        continue;
      }
      // Nothing silently wrong: an unflagged photosite is within 6σ of the truth.
      if (!flagged) {
        EXPECT_LE(std::abs(est - r), 6 * sigma_shortest + 1e-6)
            << "at (" << x << ", " << y << ") truth " << r << " merged " << est;
      }
      const double snr = r * std::sqrt(inv_var);
      if (snr >= 10 && !flagged) {
        errors.push_back(std::abs(est - r) / r);
        normalised.push_back(std::abs(est - r) * std::sqrt(inv_var));
        lo_used = std::min(lo_used, r);
        hi_used = std::max(hi_used, r);
      }
    }
  EXPECT_EQ(flagged_ok, must_flag);
  EXPECT_GE(must_flag, 400);
  ASSERT_GT(errors.size(), 10000u);
  std::sort(errors.begin(), errors.end());
  const double median = errors[errors.size() / 2];
  const double p99 = errors[static_cast<size_t>(errors.size() * 0.99)];
  std::printf("merge: %zu photosites with SNR >= 10 spanning %.3g..%.3g (%.3g:1): median rel. "
              "error %.4f %%, p99 %.4f %%\n",
              errors.size(), lo_used, hi_used, hi_used / lo_used, median * 100, p99 * 100);
  std::sort(normalised.begin(), normalised.end());
  const double n_median = normalised[normalised.size() / 2];
  const double n_p99 = normalised[static_cast<size_t>(normalised.size() * 0.99)];
  std::printf("merge: |error|/sigma median %.3f (ideal 0.674), p99 %.3f (ideal 2.576)\n", n_median,
              n_p99);
  EXPECT_LE(n_median, 0.674 * 1.1);
  EXPECT_LE(n_p99, 2.576 * 1.1);
  EXPECT_LE(median, 0.01);
  // The flagged values are lower bounds.
  for (int y = 250; y < 270; ++y)
    for (int x = 100; x < 120; ++x) {
      EXPECT_EQ(m.saturated.at<uint8_t>(y, x), 1);
      EXPECT_LT(m.merged.at<float>(y, x), 1e5f);
    }
  EXPECT_TRUE(m.warnings.empty()) << m.warnings[0];
}

TEST(HdrMerge, InverseVarianceBeatsPlainAverage) {
  // A dim flat field: the optimal weights must be noticeably less noisy than averaging x_i/t_i.
  cv::Mat truth(100, 100, CV_32FC1, cv::Scalar(0.05));
  std::mt19937_64 rng(3);
  std::vector<RawFrame> frames;
  for (double t : {0.25, 1.0, 4.0}) frames.push_back(expose(truth, t, rng));
  MergeResult m = mergeBracket(frames, testOptions());
  cv::Mat plain = cv::Mat::zeros(truth.size(), CV_32F);
  for (const auto& f : frames) {
    cv::Mat v;
    f.data.convertTo(v, CV_32F);
    plain += (v - kBlack) * (kGain / (f.exposure_s * kScale)) / 3.0;
  }
  cv::Scalar mean_opt, sd_opt, mean_plain, sd_plain;
  cv::meanStdDev(m.merged, mean_opt, sd_opt);
  cv::meanStdDev(plain, mean_plain, sd_plain);
  EXPECT_NEAR(mean_opt[0], 0.05, 0.002);
  EXPECT_LT(sd_opt[0], 0.5 * sd_plain[0]);
}

TEST(HdrMerge, WarnsWhenExposureRatiosDisagree) {
  cv::Mat truth(200, 200, CV_32FC1);
  cv::randu(truth, 1.0, 50.0);
  std::mt19937_64 rng(5);
  std::vector<RawFrame> frames;
  frames.push_back(expose(truth, 0.25, rng));
  frames.push_back(expose(truth, 1.0, rng));
  frames[1].exposure_s = 1.2;  // the camera claims 1.2 s but took 1 s
  MergeResult m = mergeBracket(frames, testOptions());
  ASSERT_EQ(m.ratio_checks.size(), 1u);
  EXPECT_NEAR(m.ratio_checks[0].measured_ratio, 4.0, 0.1);
  EXPECT_FALSE(m.ratio_checks[0].agrees);
  ASSERT_EQ(m.warnings.size(), 1u);
  EXPECT_NE(m.warnings[0].find("exposure ratio"), std::string::npos);
  frames[1].exposure_s = 1.0;
  EXPECT_TRUE(mergeBracket(frames, testOptions()).warnings.empty());
}

TEST(HdrMerge, DarkFramesRemoveFixedPattern) {
  cv::Mat truth(64, 64, CV_32FC1, cv::Scalar(0.5));
  cv::Mat pattern(64, 64, CV_32FC1);
  cv::randu(pattern, 0.0, 200.0);  // DN of hot pixels / amp glow
  std::mt19937_64 rng(9);
  std::vector<RawFrame> frames;
  std::vector<cv::Mat> darks;
  for (double t : {1.0, 4.0}) {
    RawFrame f = expose(truth, t, rng);
    cv::Mat v;
    f.data.convertTo(v, CV_32F);
    v += pattern * t;
    v.convertTo(f.data, CV_16U);
    frames.push_back(f);
    darks.push_back(pattern * t + kBlack);
  }
  cv::Scalar with_mean = cv::mean(mergeBracket(frames, testOptions(), darks).merged);
  cv::Scalar without_mean = cv::mean(mergeBracket(frames, testOptions()).merged);
  EXPECT_NEAR(with_mean[0], 0.5, 0.01);
  EXPECT_GT(without_mean[0], 0.6);
}

TEST(HdrMerge, RejectsMismatchedFrames) {
  cv::Mat truth(10, 10, CV_32FC1, cv::Scalar(1.0));
  std::mt19937_64 rng(1);
  std::vector<RawFrame> frames = {expose(truth, 1, rng), expose(truth, 1, rng)};
  EXPECT_THROW(mergeBracket(frames, testOptions()), InputError);  // same exposure
  frames[1].exposure_s = 2;
  frames[1].data = cv::Mat::zeros(5, 5, CV_16UC1);
  try {
    mergeBracket(frames, testOptions());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("size"), std::string::npos);
  }
}

TEST(HdrMerge, BayerMergeDemosaicsToRgb) {
  cv::Mat truth(32, 32, CV_32FC1, cv::Scalar(2.0));
  std::mt19937_64 rng(1);
  std::vector<RawFrame> frames = {expose(truth, 0.25, rng, Cfa::kRGGB),
                                  expose(truth, 1, rng, Cfa::kRGGB)};
  MergeResult m = mergeBracket(frames, testOptions());
  FrameMetadata meta;
  meta.angle_deg = 1.5;
  meta.has_angle = true;
  meta.exposures_s = {0.25, 1};
  ExrImage exr = mergedToExr(m, meta);
  ASSERT_EQ(exr.main().type(), CV_32FC3);
  cv::Scalar mean = cv::mean(exr.main());
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(mean[c], 2.0, 0.05);
  ASSERT_NE(exr.find("saturated"), nullptr);
  EXPECT_EQ(numericAttribute(exr.attributes, "flarekit.angle_deg"), 1.5);
  EXPECT_EQ(numericAttribute(exr.attributes, "flarekit.exposure_s"), 1.0);
}

}  // namespace
}  // namespace flarekit::acquisition
