#include "render/starburst.h"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace flarekit::render {

cv::Mat starburstPattern(const Aperture& aperture, int fft_size) {
  const int d = std::max(8, fft_size / 4);
  cv::Mat field(fft_size, fft_size, CV_32FC1, cv::Scalar(0));
  aperture.raster(d).copyTo(field(cv::Rect((fft_size - d) / 2, (fft_size - d) / 2, d, d)));
  cv::Mat spectrum;
  cv::dft(field, spectrum, cv::DFT_COMPLEX_OUTPUT);
  cv::Mat planes[2];
  cv::split(spectrum, planes);
  cv::Mat power;
  cv::magnitude(planes[0], planes[1], power);
  power = power.mul(power);
  // Move the zero frequency to the centre (fft_size / 2).
  const int h = fft_size / 2;
  cv::Mat shifted(power.size(), power.type());
  power(cv::Rect(0, 0, h, h)).copyTo(shifted(cv::Rect(h, h, h, h)));
  power(cv::Rect(h, 0, fft_size - h, h)).copyTo(shifted(cv::Rect(0, h, fft_size - h, h)));
  power(cv::Rect(0, h, h, fft_size - h)).copyTo(shifted(cv::Rect(h, 0, h, fft_size - h)));
  power(cv::Rect(h, h, fft_size - h, fft_size - h)).copyTo(shifted(cv::Rect(0, 0, fft_size - h, fft_size - h)));
  // The DFT is periodic: spikes reaching the border would wrap round. A radial window fading to
  // zero at the border keeps the pattern a single, round starburst.
  for (int y = 0; y < fft_size; ++y)
    for (int x = 0; x < fft_size; ++x) {
      const double r = std::hypot(x - h, y - h) / h;
      const double w = r < 1.0 ? (1.0 - r * r) * (1.0 - r * r) : 0.0;
      shifted.at<float>(y, x) *= static_cast<float>(w);
    }
  const double sum = cv::sum(shifted)[0];
  if (sum > 0) shifted /= sum;
  return shifted;
}

cv::Mat starburstBand(const cv::Mat& pattern, std::span<const BandWavelength> band, double* scale_nm) {
  double longest = 0;
  for (const BandWavelength& b : band) longest = std::max(longest, b.wavelength_nm);
  *scale_nm = longest;
  if (band.empty() || !(longest > 0)) return {};
  cv::Mat sum(pattern.size(), CV_32FC1, cv::Scalar(0)), copy;
  // The zero frequency is at index n/2 (starburstPattern) and stays there.
  const double c = pattern.cols / 2;
  for (const BandWavelength& b : band) {
    if (!(b.weight > 0)) continue;
    const double k = b.wavelength_nm / longest;
    const cv::Matx23d stretch(k, 0, c * (1 - k), 0, k, c * (1 - k));
    cv::warpAffine(pattern, copy, stretch, pattern.size(), cv::INTER_LINEAR, cv::BORDER_CONSTANT,
                   cv::Scalar(0));
    // Each wavelength carries its weight of the flux whatever its scale (a shrunk copy's samples
    // sum to about k² of the pattern's).
    const double s = cv::sum(copy)[0];
    if (s > 0) cv::scaleAdd(copy, b.weight / s, sum, sum);
  }
  const double total = cv::sum(sum)[0];
  if (total > 0) sum /= total;
  return sum;
}

void addStarburst(const cv::Mat& pattern, cv::Point2d center_px, double radius_px,
                  double flux_px, const cv::Vec3f& weight, cv::Mat* image) {
  if (!(flux_px > 0) || !(radius_px > 0)) return;
  const int n = pattern.cols;
  const double scale = radius_px / (n / 2.0);  // pixels per bin
  const int size = std::max(1, static_cast<int>(std::lround(n * scale)));
  if (size > 8192) return;
  cv::Mat sprite;
  if (size == n)
    sprite = pattern.clone();
  else
    cv::resize(pattern, sprite, cv::Size(size, size), 0, 0,
               size < n ? cv::INTER_AREA : cv::INTER_LINEAR);
  const double s = cv::sum(sprite)[0];
  if (!(s > 0)) return;
  sprite *= flux_px / s;
  // The zero frequency (bin n/2, whose centre is at n/2 + 0.5 in the pattern's pixel-edge
  // coordinates, size/n sprite pixels per bin) goes to center_px, by an integer offset plus a
  // bilinear sub-pixel shift.
  const double zero = (n / 2 + 0.5) * size / n;
  const double ox = center_px.x - zero, oy = center_px.y - zero;
  const int ix = static_cast<int>(std::floor(ox)), iy = static_cast<int>(std::floor(oy));
  const float fx = static_cast<float>(ox - ix), fy = static_cast<float>(oy - iy);
  const float w[2][2] = {{(1 - fx) * (1 - fy), fx * (1 - fy)}, {(1 - fx) * fy, fx * fy}};
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const float v = sprite.at<float>(y, x);
      if (v == 0.0f) continue;
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b) {
          const int px = ix + x + b, py = iy + y + a;
          if (px < 0 || py < 0 || px >= image->cols || py >= image->rows) continue;
          image->at<cv::Vec3f>(py, px) += weight * (v * w[a][b]);
        }
    }
}

void addHalo(cv::Point2d center_px, double radius_px, double flux_px, const cv::Vec3f& weight,
             cv::Mat* image) {
  if (!(flux_px > 0) || !(radius_px > 0)) return;
  const double cut = 4.0 * radius_px;
  const int x0 = std::max(0, static_cast<int>(std::floor(center_px.x - cut)));
  const int x1 = std::min(image->cols - 1, static_cast<int>(std::ceil(center_px.x + cut)));
  const int y0 = std::max(0, static_cast<int>(std::floor(center_px.y - cut)));
  const int y1 = std::min(image->rows - 1, static_cast<int>(std::ceil(center_px.y + cut)));
  if (x0 > x1 || y0 > y1) return;
  // Normalise over the whole disc (not only the visible part) so the halo does not brighten
  // when the light leaves the image.
  double total = 0.0;
  const int r = static_cast<int>(std::ceil(cut));
  for (int y = -r; y <= r; ++y)
    for (int x = -r; x <= r; ++x) {
      const double q = std::hypot(x, y);
      if (q <= cut) total += std::pow(1.0 + (q / radius_px) * (q / radius_px), -1.5);
    }
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const double q = std::hypot(x + 0.5 - center_px.x, y + 0.5 - center_px.y);
      if (q > cut) continue;
      const double v = flux_px * std::pow(1.0 + (q / radius_px) * (q / radius_px), -1.5) / total;
      image->at<cv::Vec3f>(y, x) += weight * static_cast<float>(v);
    }
}

}  // namespace flarekit::render
