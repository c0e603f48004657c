#include "render/metrics.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "core/error.h"

namespace rouen {

namespace {

void Check(const Image& r, const Image& t, const std::vector<uint8_t>& mask) {
  if (r.width != t.width || r.height != t.height) {
    throw Error("metrics: rendered image is " + std::to_string(r.width) + "x" +
                std::to_string(r.height) + ", truth " + std::to_string(t.width) + "x" +
                std::to_string(t.height));
  }
  if (r.channels < 3 || t.channels < 3) throw Error("metrics: images need 3 channels");
  if (!mask.empty() && mask.size() != static_cast<size_t>(r.width) * r.height) {
    throw Error("metrics: mask has " + std::to_string(mask.size()) + " entries, expected " +
                std::to_string(static_cast<size_t>(r.width) * r.height));
  }
}

template <typename F>
int64_t ForMasked(const Image& r, const Image& t, const std::vector<uint8_t>& mask, F f) {
  int64_t n = 0;
  for (int y = 0; y < r.height; ++y) {
    for (int x = 0; x < r.width; ++x) {
      if (!mask.empty() && mask[static_cast<size_t>(y) * r.width + x] == 0) continue;
      ++n;
      for (int c = 0; c < 3; ++c) {
        const double a = r.at(x, y, c), b = t.at(x, y, c);
        if (!std::isfinite(a) || !std::isfinite(b)) {
          throw Error("metrics: non-finite value at pixel (" + std::to_string(x) + ", " +
                      std::to_string(y) + ")");
        }
        f(a, b);
      }
    }
  }
  if (n == 0) throw Error("metrics: the mask selects no pixels");
  return n;
}

}  // namespace

RenderMetrics CompareRadiance(const Image& rendered, const Image& truth,
                              const std::vector<uint8_t>& mask, double s) {
  Check(rendered, truth, mask);
  if (!(s > 0) || !std::isfinite(s)) throw Error("metrics: scale must be positive and finite");
  RenderMetrics m;
  m.scale = s;
  double se = 0, st = 0, sr = 0, sum_t = 0;
  std::vector<double> tv;
  m.pixels = ForMasked(rendered, truth, mask, [&](double a, double b) {
    se += (s * a - b) * (s * a - b);
    st += b * b;
    sr += s * a;
    sum_t += b;
    tv.push_back(b);
  });
  m.rel_rmse = st > 0 ? std::sqrt(se / st) : (se > 0 ? INFINITY : 0.0);
  m.mean_ratio = sum_t > 0 ? sr / sum_t : 0.0;
  const size_t k = std::min(tv.size() - 1, static_cast<size_t>(0.99 * (tv.size() - 1)));
  std::nth_element(tv.begin(), tv.begin() + k, tv.end());
  const double norm = tv[k] > 0 ? tv[k] : 1.0;
  double mse = 0;
  int64_t count = 0;
  ForMasked(rendered, truth, mask, [&](double a, double b) {
    const double d = std::clamp(s * a / norm, 0.0, 1.0) - std::clamp(b / norm, 0.0, 1.0);
    mse += d * d;
    ++count;
  });
  mse /= count;
  m.psnr_db = mse > 0 ? 10 * std::log10(1.0 / mse) : 99.0;
  if (!std::isfinite(m.rel_rmse)) throw Error("metrics: the masked truth is all zero");
  return m;
}

std::vector<uint8_t> ErodeMask(const std::vector<uint8_t>& mask, int width, int height,
                               int radius) {
  if (width < 0 || height < 0 || mask.size() != static_cast<size_t>(width) * height) {
    throw Error("metrics: mask has " + std::to_string(mask.size()) + " entries for a " +
                std::to_string(width) + "x" + std::to_string(height) + " image");
  }
  if (radius < 0) throw Error("metrics: erosion radius must be >= 0");
  std::vector<uint8_t> out(mask.size(), 0);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      bool keep = true;
      for (int dy = -radius; dy <= radius && keep; ++dy) {
        for (int dx = -radius; dx <= radius && keep; ++dx) {
          const int xx = x + dx, yy = y + dy;
          keep = xx >= 0 && yy >= 0 && xx < width && yy < height &&
                 mask[static_cast<size_t>(yy) * width + xx] != 0;
        }
      }
      out[static_cast<size_t>(y) * width + x] = keep ? 1 : 0;
    }
  }
  return out;
}

double FitScale(const Image& rendered, const Image& truth, const std::vector<uint8_t>& mask) {
  Check(rendered, truth, mask);
  double rt = 0, rr = 0;
  ForMasked(rendered, truth, mask, [&](double a, double b) {
    rt += a * b;
    rr += a * a;
  });
  if (!(rr > 0)) throw Error("metrics: the rendered image is zero over the mask");
  return rt / rr;
}

}  // namespace rouen
