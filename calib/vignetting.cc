#include "calib/vignetting.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Dense>
#include <nlohmann/json.hpp>

#include "core/error.h"

namespace rouen {
namespace {

double HalfDiagonal(int w, int h) { return 0.5 * std::hypot(double(w), double(h)); }

// One bin of one flat frame: centre (pixels) and mean linear level.
struct Bin {
  int frame;
  double x, y, value;
};

}  // namespace

double VignettingModel::FalloffAtRadius(double r) const {
  const double p = r * r;
  return 1 + p * (a[0] + p * (a[1] + p * a[2]));
}

double VignettingModel::Falloff(double x, double y) const {
  const double hd = HalfDiagonal(width, height);
  return FalloffAtRadius(std::hypot(x - cx, y - cy) / hd);
}

double VignettingModel::MaxRadius() const {
  const double hd = HalfDiagonal(width, height);
  double r = 0;
  for (double x : {0.0, double(width)})
    for (double y : {0.0, double(height)}) r = std::max(r, std::hypot(x - cx, y - cy) / hd);
  return r;
}

void VignettingModel::Validate() const {
  if (width <= 0 || height <= 0) throw Error("vignetting: width and height must be positive");
  if (!std::isfinite(cx) || !std::isfinite(cy) || cx < 0 || cx > width || cy < 0 || cy > height)
    throw Error("vignetting: the optical centre must lie inside the image");
  for (double v : a)
    if (!std::isfinite(v)) throw Error("vignetting: coefficients must be finite");
  const double rmax = MaxRadius();
  for (int i = 0; i <= 200; ++i) {
    const double r = rmax * i / 200;
    if (!(FalloffAtRadius(r) > 0.05))
      throw Error("vignetting: the fall-off drops to " + std::to_string(FalloffAtRadius(r)) +
                  " at radius " + std::to_string(r) + " (must stay above 0.05)");
  }
}

void to_json(nlohmann::json& j, const VignettingModel& v) {
  j = {{"model", "radial-even-6"},
       {"width", v.width},
       {"height", v.height},
       {"cx", v.cx},
       {"cy", v.cy},
       {"a", {v.a[0], v.a[1], v.a[2]}}};
}

void from_json(const nlohmann::json& j, VignettingModel& v) {
  if (!j.is_object()) throw Error("vignetting: expected an object");
  if (j.contains("model") && j["model"] != "radial-even-6")
    throw Error("vignetting: unknown model (expected \"radial-even-6\")");
  VignettingModel r;
  try {
    r.width = j.at("width").get<int>();
    r.height = j.at("height").get<int>();
    r.cx = j.at("cx").get<double>();
    r.cy = j.at("cy").get<double>();
    const auto& a = j.at("a");
    if (!a.is_array() || a.size() != 3) throw Error("vignetting: \"a\" must be [a1, a2, a3]");
    for (int k = 0; k < 3; ++k) r.a[k] = a[k].get<double>();
  } catch (const nlohmann::json::exception& e) {
    throw Error(std::string("vignetting: missing or mistyped key (width, height, cx, cy, a): ") +
                e.what());
  }
  r.Validate();
  v = r;
}

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
      throw Error("vignetting: flat frame " + std::to_string(k) + " is neither radiance nor digital");
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
  const double hd = HalfDiagonal(w, h);
  const bool grad = options.fit_gradient, centre = options.fit_centre;
  // Parameters: per frame level s (and gradient gx, gy), then a1..a3, then cx, cy.
  const int per = grad ? 3 : 1;
  const int ia = nf * per, ic = ia + 3;
  const int np = ic + (centre ? 2 : 0);
  const int min_bins = np + 10;
  if (static_cast<int>(bins.size()) < min_bins)
    throw Error("vignetting: only " + std::to_string(bins.size()) +
                " usable bins (need " + std::to_string(min_bins) +
                "); the flat frames are too dark, saturated or small");

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

void RemoveVignetting(const VignettingModel& model, Image* radiance) {
  if (radiance->units != PixelUnits::kRadiance)
    throw Error("vignetting: can only be removed from a radiance image");
  const int w = radiance->width, h = radiance->height;
  if (w <= 0 || h <= 0) return;
  const double sx = double(model.width) / w, sy = double(model.height) / h;
  if (std::abs(sx / sy - 1) > 0.01)
    throw Error("vignetting: the model is for " + std::to_string(model.width) + "x" +
                std::to_string(model.height) + " images, this one is " + std::to_string(w) + "x" +
                std::to_string(h) + " (another aspect ratio)");
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const double v = model.Falloff((x + 0.5) * sx, (y + 0.5) * sy);
      const float inv = static_cast<float>(1 / std::max(v, 0.05));
      for (int c = 0; c < radiance->channels; ++c) radiance->at(x, y, c) *= inv;
    }
  }
}

}  // namespace rouen
