#include "calib/vignetting.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>

#include "core/error.h"

namespace rouen {
namespace {

// One bin of one flat frame: centre (pixels) and mean linear level.
struct Bin {
  int frame;
  double x, y, value;
};

}  // namespace

void VignettingOptions::Validate() const {
  if (bin < 1 || bin > 256) throw Error("vignetting options: bin must be 1..256 pixels");
  if (fit_centre && fit_gradient)
    throw Error(
        "vignetting options: fit_centre needs fit_gradient off (a centre offset and a linear "
        "gradient are the same to first order)");
  if (!(dark_level >= 0 && saturation_level > dark_level && saturation_level <= 255))
    throw Error("vignetting options: need 0 <= dark_level < saturation_level <= 255");
  if (max_iterations < 1) throw Error("vignetting options: max_iterations must be positive");
  if (!std::isfinite(centre[0]) || !std::isfinite(centre[1]))
    throw Error("vignetting options: centre must be finite");
}

VignettingModel FitVignetting(const std::vector<const Image*>& flats,
                              const VignettingOptions& options, const ResponseCurve* curve,
                              VignettingSummary* summary) {
  options.Validate();
  if (flats.empty() || !flats[0]) throw Error("vignetting: no flat-field frames");
  const int w = flats[0]->width, h = flats[0]->height;
  for (size_t k = 0; k < flats.size(); ++k) {
    const Image* f = flats[k];
    if (!f || f->empty()) throw Error("vignetting: flat frame " + std::to_string(k) + " is empty");
    if (f->width != w || f->height != h)
      throw Error("vignetting: flat frame " + std::to_string(k) + " is " +
                  std::to_string(f->width) + "x" + std::to_string(f->height) + ", frame 0 is " +
                  std::to_string(w) + "x" + std::to_string(h));
    if (f->units == PixelUnits::kDigital) {
      if (!curve || !curve->valid())
        throw Error("vignetting: flat frame " + std::to_string(k) +
                    " holds digital numbers; a response curve is needed to linearise it");
    } else if (f->units != PixelUnits::kRadiance) {
      throw Error("vignetting: flat frame " + std::to_string(k) +
                  " is neither radiance nor digital");
    }
  }
  const int bin = options.bin;
  const int bx = w / bin, by = h / bin;
  if (bx < 4 || by < 4)
    throw Error("vignetting: the frames are too small for " + std::to_string(bin) +
                "-pixel bins (need at least 4 x 4 bins)");

  // Bin means of the linear level (mean over channels); a bin with any unusable pixel is
  // dropped.
  std::vector<Bin> bins;
  for (size_t k = 0; k < flats.size(); ++k) {
    const Image& f = *flats[k];
    const bool digital = f.units == PixelUnits::kDigital;
    for (int j = 0; j < by; ++j) {
      for (int i = 0; i < bx; ++i) {
        double sum = 0;
        bool ok = true;
        for (int y = j * bin; y < (j + 1) * bin && ok; ++y) {
          for (int x = i * bin; x < (i + 1) * bin && ok; ++x) {
            for (int c = 0; c < f.channels; ++c) {
              const double v = f.at(x, y, c);
              if (!std::isfinite(v)) {
                ok = false;
                break;
              }
              if (digital) {
                if (v <= options.dark_level || v >= options.saturation_level) {
                  ok = false;
                  break;
                }
                sum += std::exp(curve->LogExposure(std::min(c, 2), v));
              } else {
                if (!(v > 0)) {
                  ok = false;
                  break;
                }
                sum += v;
              }
            }
          }
        }
        if (!ok) continue;
        bins.push_back({static_cast<int>(k), (i + 0.5) * bin, (j + 0.5) * bin,
                        sum / (double(bin) * bin * f.channels)});
      }
    }
  }

  const int nf = static_cast<int>(flats.size());
  VignettingModel m;
  m.width = w;
  m.height = h;
  m.cx = options.centre[0] >= 0 ? options.centre[0] : w / 2.0;
  m.cy = options.centre[1] >= 0 ? options.centre[1] : h / 2.0;
  const double hd = VignettingModel::HalfDiagonal(w, h);
  const bool grad = options.fit_gradient, centre = options.fit_centre;
  // Parameters: per frame level s (and gradient gx, gy), then a1..a3, then cx, cy.
  const int per = grad ? 3 : 1;
  const int ia = nf * per, ic = ia + 3;
  const int np = ic + (centre ? 2 : 0);
  const int min_bins = np + 10;
  if (static_cast<int>(bins.size()) < min_bins)
    throw Error("vignetting: only " + std::to_string(bins.size()) + " usable bins (need " +
                std::to_string(min_bins) + "); the flat frames are too dark, saturated or small");

  Eigen::VectorXd p = Eigen::VectorXd::Zero(np);
  std::vector<double> scale(nf, 0);  // initial level: residuals are relative to it
  {
    std::vector<double> sum(nf, 0), n(nf, 0);
    for (const Bin& b : bins) {
      if (std::hypot(b.x - m.cx, b.y - m.cy) / hd < 0.3) {
        sum[b.frame] += b.value;
        n[b.frame] += 1;
      }
    }
    std::vector<double> all(nf, 0), nall(nf, 0);
    for (const Bin& b : bins) {
      all[b.frame] += b.value;
      nall[b.frame] += 1;
    }
    for (int k = 0; k < nf; ++k) {
      if (nall[k] == 0)
        throw Error("vignetting: flat frame " + std::to_string(k) + " has no usable bin");
      scale[k] = n[k] > 0 ? sum[k] / n[k] : all[k] / nall[k];
      p[k * per] = scale[k];
    }
  }
  if (centre) {
    p[ic] = m.cx;
    p[ic + 1] = m.cy;
  }

  // Residuals e = (model - value) / scale_k, model = s (1 + gx u + gy v) V(rho).
  auto evaluate = [&](const Eigen::VectorXd& q, Eigen::MatrixXd* jtj, Eigen::VectorXd* jte) {
    double cost = 0;
    if (jtj) {
      jtj->setZero(np, np);
      jte->setZero(np);
    }
    const double cxq = centre ? q[ic] : m.cx, cyq = centre ? q[ic + 1] : m.cy;
    Eigen::VectorXd row(np);
    std::vector<int> idx;
    for (const Bin& b : bins) {
      const int o = b.frame * per;
      const double s = q[o];
      const double u = (b.x - w / 2.0) / hd, v = (b.y - h / 2.0) / hd;
      const double gl = grad ? 1 + q[o + 1] * u + q[o + 2] * v : 1;
      const double dx = b.x - cxq, dy = b.y - cyq;
      const double rho = (dx * dx + dy * dy) / (hd * hd);
      const double a1 = q[ia], a2 = q[ia + 1], a3 = q[ia + 2];
      const double vf = 1 + rho * (a1 + rho * (a2 + rho * a3));
      const double inv = 1 / scale[b.frame];
      const double e = (s * gl * vf - b.value) * inv;
      cost += e * e;
      if (!jtj) continue;
      idx.clear();
      row.setZero();
      row[o] = gl * vf * inv;
      idx.push_back(o);
      if (grad) {
        row[o + 1] = s * u * vf * inv;
        row[o + 2] = s * v * vf * inv;
        idx.push_back(o + 1);
        idx.push_back(o + 2);
      }
      row[ia] = s * gl * rho * inv;
      row[ia + 1] = s * gl * rho * rho * inv;
      row[ia + 2] = s * gl * rho * rho * rho * inv;
      idx.push_back(ia);
      idx.push_back(ia + 1);
      idx.push_back(ia + 2);
      if (centre) {
        const double dv = a1 + 2 * a2 * rho + 3 * a3 * rho * rho;
        row[ic] = s * gl * dv * (-2 * dx / (hd * hd)) * inv;
        row[ic + 1] = s * gl * dv * (-2 * dy / (hd * hd)) * inv;
        idx.push_back(ic);
        idx.push_back(ic + 1);
      }
      for (int r : idx) {
        (*jte)[r] += row[r] * e;
        for (int c : idx) (*jtj)(r, c) += row[r] * row[c];
      }
    }
    return cost;
  };

  // Levenberg-Marquardt on the small dense normal equations.
  double lambda = 1e-3;
  Eigen::MatrixXd jtj;
  Eigen::VectorXd jte;
  double cost = evaluate(p, &jtj, &jte);
  int it = 0;
  for (; it < options.max_iterations; ++it) {
    bool improved = false;
    for (int tries = 0; tries < 10 && !improved; ++tries) {
      Eigen::MatrixXd a = jtj;
      for (int i = 0; i < np; ++i) a(i, i) += lambda * (jtj(i, i) + 1e-12);
      const Eigen::VectorXd step = a.ldlt().solve(-jte);
      if (!step.allFinite()) {
        lambda *= 10;
        continue;
      }
      const Eigen::VectorXd q = p + step;
      const double c = evaluate(q, nullptr, nullptr);
      if (std::isfinite(c) && c < cost) {
        const double gain = cost - c;
        p = q;
        cost = c;
        lambda = std::max(lambda / 10, 1e-12);
        improved = true;
        if (gain < 1e-12 * (1 + cost)) it = options.max_iterations;  // converged
      } else {
        lambda *= 10;
      }
    }
    if (!improved) break;
    if (it < options.max_iterations) cost = evaluate(p, &jtj, &jte);
  }

  m.a = {p[ia], p[ia + 1], p[ia + 2]};
  if (centre) {
    m.cx = p[ic];
    m.cy = p[ic + 1];
  }
  try {
    m.Validate();
  } catch (const Error& e) {
    throw Error(std::string("vignetting: the fit did not give a usable model: ") + e.what());
  }
  if (summary) {
    VignettingSummary s;
    s.frames = nf;
    s.bins_used = static_cast<int>(bins.size());
    s.iterations = std::min(it, options.max_iterations);
    // Relative residual per bin.
    double sse = 0;
    for (const Bin& b : bins) {
      const int o = b.frame * per;
      const double u = (b.x - w / 2.0) / hd, v = (b.y - h / 2.0) / hd;
      const double gl = grad ? 1 + p[o + 1] * u + p[o + 2] * v : 1;
      const double model = p[o] * gl * m.Falloff(b.x, b.y);
      sse += std::pow((b.value - model) / model, 2);
    }
    s.residual_rms = std::sqrt(sse / bins.size());
    s.corner_falloff = m.FalloffAtRadius(m.MaxRadius());
    if (grad) {
      for (int k = 0; k < nf; ++k) {
        s.gradient_max[0] = std::max(s.gradient_max[0], std::abs(p[k * per + 1]) * w / hd);
        s.gradient_max[1] = std::max(s.gradient_max[1], std::abs(p[k * per + 2]) * w / hd);
      }
    }
    *summary = s;
  }
  return m;
}

}  // namespace rouen
