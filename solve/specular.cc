#include "solve/specular.h"

#include <ceres/ceres.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>

#include "core/error.h"
#include "core/text.h"

namespace rouen {

double SpecularLobe::Shape(const Eigen::Vector3d& normal, const Eigen::Vector3d& u,
                           const Eigen::Vector3d& v) const {
  return LobeShape(model, kappa, n, u.dot(normal), v.dot(normal), u.dot(v));
}

double SpecularLobe::MirrorExponent() const {
  return model == LobeModel::kMicrofacet ? (n + 2) / 8 : n;
}

std::string SpecularLobe::Text() const {
  if (model == LobeModel::kMicrofacet)
    return Formatted("microfacet rho_s %.3g/%.3g/%.3g, alpha %.3f", rho_s[0], rho_s[1], rho_s[2],
                     std::sqrt(2 / (n + 2)));
  return Formatted("rho_s %.3g/%.3g/%.3g, kappa %.2f, n %.0f", rho_s[0], rho_s[1], rho_s[2], kappa,
                   n);
}

const char* LobeModelName(LobeModel model) {
  return model == LobeModel::kMicrofacet ? "microfacet" : "lafortune";
}

LobeModel ParseLobeModel(const std::string& name, const std::string& what) {
  if (name == "lafortune") return LobeModel::kLafortune;
  if (name == "microfacet") return LobeModel::kMicrofacet;
  throw Error(what + ": unknown lobe model '" + name + "' (lafortune or microfacet)");
}

void SpecularLobe::Validate(const std::string& what) const {
  if (!rho_s.allFinite() || rho_s.minCoeff() < 0)
    throw Error(what + ": specular rho_s must be finite and >= 0");
  if (!(kappa >= kLobeKappaMin && kappa <= kLobeKappaMax))
    throw Error(what + ": specular kappa " + std::to_string(kappa) + " outside [" +
                std::to_string(kLobeKappaMin) + ", " + std::to_string(kLobeKappaMax) + "]");
  if (model == LobeModel::kMicrofacet && kappa != 1)
    throw Error(what + ": a microfacet lobe has kappa 1");
  if (!(n >= kLobeExponentMin && n <= kLobeExponentMax))
    throw Error(what + ": specular exponent " + std::to_string(n) + " outside [" +
                std::to_string(kLobeExponentMin) + ", " + std::to_string(kLobeExponentMax) + "]");
  if (rho_s.maxCoeff() > MaxLobeRho(n, model) * (1 + 1e-9))
    throw Error(what + ": specular rho_s above " +
                (model == LobeModel::kMicrofacet ? "(n + 2) / 8 pi" : "(n + 2) / 2 pi") +
                ": the lobe would reflect more light than it receives");
  if (kappa > 1 && n * std::log(kappa) > std::log(kLobeMaxGrazingGain) * (1 + 1e-9))
    throw Error(what + ": specular kappa^n above " + std::to_string(kLobeMaxGrazingGain));
}

double MaxLobeRho(double n, LobeModel model) {
  return (n + 2) / (model == LobeModel::kMicrofacet ? 8 * M_PI : 2 * M_PI);
}

double PaperRho(double z) {
  // tanh(|z| / 4) through one exp, as eq. 15 writes it (glibc's tanh costs several exp: the
  // sun lobe's global search spent a sixth of a demo solve in it).
  const double e = std::exp(-0.5 * std::abs(z));
  return (1 - e) / (1 + e);
}

Eigen::Vector3d DrawAboutAxis(const Eigen::Vector3d& axis, double exponent, double u1, double u2) {
  const Eigen::Vector3d t1 = axis.unitOrthogonal(), t2 = axis.cross(t1);
  const double cos_a = std::pow(u1, 1.0 / (exponent + 1));
  const double sin_a = std::sqrt(std::max(0.0, 1 - cos_a * cos_a));
  const double phi = 2 * M_PI * u2;
  return cos_a * axis + sin_a * (std::cos(phi) * t1 + std::sin(phi) * t2);
}

double MixtureWeight(const Eigen::Vector3d& n, const Eigen::Vector3d& m, const Eigen::Vector3d& u,
                     double exponent, int cosine_count, int mirror_count) {
  const double cu = u.dot(n);
  if (!(cu > 0)) return 0;
  const double cm = std::max(0.0, u.dot(m));
  const double density = cosine_count * cu / M_PI +
                         mirror_count * (exponent + 1) / (2 * M_PI) * std::pow(cm, exponent);
  return density > 0 ? cu / density : 0;
}

double LobeDirectionalAlbedo(const SpecularLobe& lobe, double cos_view, int strata) {
  if (!(cos_view > 0)) return 0;
  const double c = std::min(cos_view, 1.0);
  const Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d v(std::sqrt(1 - c * c), 0, c), m(-v.x(), 0, c);
  const double e = lobe.MirrorExponent();
  const int count = strata * strata;
  double sum = 0;
  for (int a = 0; a < strata; ++a) {
    for (int b = 0; b < strata; ++b) {
      const double u1 = (a + 0.5) / strata, u2 = (b + 0.5) / strata;
      for (const Eigen::Vector3d& u : {DrawAboutAxis(m, e, u1, u2), DrawAboutAxis(n, 1, u1, u2)})
        sum += lobe.Shape(n, u, v) * MixtureWeight(n, m, u, e, count, count);
    }
  }
  return sum;
}

void SunLobeOptions::Validate() const {
  if (min_samples < 1) throw Error("sun lobe: min_samples must be >= 1");
  if (max_samples < min_samples) throw Error("sun lobe: max_samples must be >= min_samples");
  if (!(min_gain >= 0 && min_gain <= 1)) throw Error("sun lobe: min_gain must be in [0, 1]");
  if (kappa_steps < 1 || exponent_steps < 2)
    throw Error("sun lobe: kappa_steps must be >= 1 and exponent_steps >= 2");
  if (simplex_iterations < 0) throw Error("sun lobe: simplex_iterations must be >= 0");
}

namespace {

// A sample reduced to what the cost needs: u.n, v.n and u.v, and per channel E / sigma and
// residual / sigma.
struct Term {
  double un = 0, vn = 0, uv = 0;
  std::array<double, 3> e{}, r{};
};

std::vector<Term> Terms(const std::vector<LobeSample>& samples) {
  std::vector<Term> t;
  t.reserve(samples.size());
  for (const LobeSample& s : samples) {
    Term q;
    q.un = s.to_light.dot(s.normal);
    q.vn = s.to_viewer.dot(s.normal);
    q.uv = s.to_light.dot(s.to_viewer);
    for (int c = 0; c < 3; ++c) {
      q.e[c] = s.irradiance[c] / s.sigma[c];
      q.r[c] = s.residual[c] / s.sigma[c];
    }
    t.push_back(q);
  }
  return t;
}

// For a lobe shape (kappa, n): each channel's best rho_s >= 0 and the whole cost. A term
// rho(r - rho_s g) is concave in rho_s on each side of its zero r / g, so the 1-D cost is
// concave between consecutive zeros and its minimum lies at a zero or at 0: the candidates are
// the zeros (a quantile subset of them when there are many, then the zeros next to the best).
struct ShapeFit {
  Eigen::Vector3d rho_s = Eigen::Vector3d::Zero();
  double cost = 0;
};

ShapeFit FitShape(const std::vector<Term>& terms, const std::array<double, 3>& cost_zero,
                  LobeModel model, double kappa, double n) {
  constexpr size_t kAllZeros = 128, kQuantiles = 64, kNeighbours = 8;
  if (kappa > 1 && n * std::log(kappa) > std::log(kLobeMaxGrazingGain)) {
    return {Eigen::Vector3d::Zero(), std::numeric_limits<double>::infinity()};
  }
  const double rho_max = MaxLobeRho(n, model);
  std::vector<double> g;
  std::vector<int> idx;
  g.reserve(terms.size());
  idx.reserve(terms.size());
  for (size_t i = 0; i < terms.size(); ++i) {
    const Term& q = terms[i];
    const double shape = LobeShape(model, kappa, n, q.un, q.vn, q.uv);
    if (!(shape > 1e-9)) continue;
    g.push_back(shape);
    idx.push_back(static_cast<int>(i));
  }
  ShapeFit fit;
  std::array<double, 3> cost{};
  tbb::parallel_for(0, 3, [&](int c) {
    // Terms the lobe leaves at zero cost the same as without it.
    double base = cost_zero[c];
    std::vector<double> gi(g.size()), ri(g.size()), zeros;
    for (size_t k = 0; k < g.size(); ++k) {
      const Term& q = terms[idx[k]];
      gi[k] = g[k] * q.e[c];
      ri[k] = q.r[c];
      base -= PaperRho(ri[k]);
      if (gi[k] > 0 && ri[k] > 0) zeros.push_back(std::min(ri[k] / gi[k], rho_max));
    }
    auto cost_at = [&](double rho) {
      double s = base;
      for (size_t k = 0; k < gi.size(); ++k) s += PaperRho(ri[k] - rho * gi[k]);
      return s;
    };
    std::sort(zeros.begin(), zeros.end());
    double best_rho = 0, best = cost_at(0);
    auto consider = [&](double rho) {
      const double v = cost_at(rho);
      if (v < best) {
        best = v;
        best_rho = rho;
      }
    };
    if (zeros.size() <= kAllZeros) {
      for (double z : zeros) consider(z);
    } else {
      size_t best_k = zeros.size();
      for (size_t q = 0; q < kQuantiles; ++q) {
        const size_t k = (q * (zeros.size() - 1)) / (kQuantiles - 1);
        const double before = best;
        consider(zeros[k]);
        if (best < before) best_k = k;
      }
      if (best_k < zeros.size()) {
        const size_t lo = best_k > kNeighbours ? best_k - kNeighbours : 0;
        const size_t hi = std::min(zeros.size(), best_k + kNeighbours + 1);
        for (size_t k = lo; k < hi; ++k) consider(zeros[k]);
      }
    }
    fit.rho_s[c] = best_rho;
    cost[c] = best;
  });
  fit.cost = cost[0] + cost[1] + cost[2];
  return fit;
}

}  // namespace

double SunLobeCost(const std::vector<LobeSample>& samples, const SpecularLobe& lobe) {
  double cost = 0;
  for (const LobeSample& s : samples) {
    const Eigen::Vector3d f = lobe.Eval(s.normal, s.to_light, s.to_viewer);
    for (int c = 0; c < 3; ++c)
      cost += PaperRho((s.residual[c] - f[c] * s.irradiance[c]) / s.sigma[c]);
  }
  return cost;
}

// §4.2.2, eq. 15: robust estimation of the sun lobe by a global search.
LobeFit FitSunLobe(const std::vector<LobeSample>& all, const SunLobeOptions& options,
                   const std::function<bool(const SpecularLobe&)>& admissible) {
  options.Validate();
  if (!options.model) {
    SunLobeOptions one = options;
    one.model = LobeModel::kLafortune;
    const LobeFit lafortune = FitSunLobe(all, one, admissible);
    one.model = LobeModel::kMicrofacet;
    const LobeFit microfacet = FitSunLobe(all, one, admissible);
    return microfacet.cost < lafortune.cost ? microfacet : lafortune;
  }
  LobeFit out;
  // Only samples that can carry information: finite, lit, sigma > 0.
  std::vector<LobeSample> usable;
  for (const LobeSample& s : all) {
    if (s.irradiance.allFinite() && s.residual.allFinite() && s.sigma.allFinite() &&
        s.sigma.minCoeff() > 0 && s.irradiance.maxCoeff() > 0 && s.normal.allFinite() &&
        s.to_light.allFinite() && s.to_viewer.allFinite())
      usable.push_back(s);
  }
  std::vector<LobeSample> samples;
  if (static_cast<int>(usable.size()) > options.max_samples) {
    for (int k = 0; k < options.max_samples; ++k)
      samples.push_back(usable[(static_cast<size_t>(k) * usable.size()) / options.max_samples]);
  } else {
    samples = std::move(usable);
  }
  out.samples = static_cast<int>(samples.size());
  const std::vector<Term> terms = Terms(samples);
  std::array<double, 3> cost_zero{};
  for (const Term& q : terms)
    for (int c = 0; c < 3; ++c) cost_zero[c] += PaperRho(q.r[c]);
  out.cost_zero = out.cost = cost_zero[0] + cost_zero[1] + cost_zero[2];
  if (out.samples < options.min_samples) return out;

  // The grid over kappa and log n.
  const double log_min = std::log(kLobeExponentMin), log_max = std::log(kLobeExponentMax);
  // The microfacet lobe has no kappa: the search is over log n alone.
  const LobeModel model = *options.model;
  const bool microfacet = model == LobeModel::kMicrofacet;
  const int nk = microfacet ? 1 : options.kappa_steps, nn = options.exponent_steps;
  const double kappa_lo = microfacet ? 1 : kLobeKappaMin, kappa_hi = microfacet ? 1 : kLobeKappaMax;
  auto kappa_at = [&](int k) {
    return nk == 1 ? 1.0 : kLobeKappaMin + (kLobeKappaMax - kLobeKappaMin) * k / (nk - 1);
  };
  // A shape's best rho_s and cost, infinite where `admissible` refuses the lobe.
  auto fit_shape = [&](double kappa, double n) {
    ShapeFit f = FitShape(terms, cost_zero, model, kappa, n);
    if (admissible && !f.rho_s.isZero() && std::isfinite(f.cost)) {
      SpecularLobe l;
      l.rho_s = f.rho_s;
      l.kappa = kappa;
      l.n = n;
      l.model = model;
      if (!admissible(l)) f.cost = std::numeric_limits<double>::infinity();
    }
    return f;
  };
  std::vector<ShapeFit> grid(static_cast<size_t>(nk) * nn);
  tbb::parallel_for(0, nk * nn, [&](int i) {
    const int k = i / nn, j = i % nn;
    grid[i] = fit_shape(kappa_at(k), std::exp(log_min + (log_max - log_min) * j / (nn - 1)));
  });
  int best_i = 0;
  for (int i = 1; i < nk * nn; ++i) {
    if (grid[i].cost < grid[best_i].cost) best_i = i;
  }
  // Downhill simplex over (kappa, log n) from the best grid point, steps of one grid cell,
  // the parameters clamped to their ranges.
  using P = Eigen::Vector2d;
  auto clamp = [&](P p) {
    return P(std::clamp(p[0], kappa_lo, kappa_hi), std::clamp(p[1], log_min, log_max));
  };
  auto eval = [&](const P& p) { return fit_shape(p[0], std::exp(p[1])); };
  const double dk = nk == 1 ? 0.1 : (kLobeKappaMax - kLobeKappaMin) / (nk - 1);
  const double dn = (log_max - log_min) / (nn - 1);
  const P start(kappa_at(best_i / nn), log_min + dn * (best_i % nn));
  std::array<P, 3> v = {start, clamp(start + P(dk, 0)), clamp(start + P(0, dn))};
  if (v[1] == start) v[1] = clamp(start - P(dk, 0));
  if (v[1] == start) v[1] = clamp(start - P(0, dn));  // one dimension: a simplex on a line
  if (v[2] == start) v[2] = clamp(start - P(0, dn));
  std::array<ShapeFit, 3> f = {grid[best_i], eval(v[1]), eval(v[2])};
  for (int it = 0; it < options.simplex_iterations; ++it) {
    std::array<int, 3> o = {0, 1, 2};
    std::sort(o.begin(), o.end(), [&](int a, int b) { return f[a].cost < f[b].cost; });
    const P centroid = 0.5 * (v[o[0]] + v[o[1]]);
    const P reflected = clamp(centroid + (centroid - v[o[2]]));
    const ShapeFit fr = eval(reflected);
    if (fr.cost < f[o[0]].cost) {
      const P expanded = clamp(centroid + 2 * (centroid - v[o[2]]));
      const ShapeFit fe = eval(expanded);
      const bool take_e = fe.cost < fr.cost;
      v[o[2]] = take_e ? expanded : reflected;
      f[o[2]] = take_e ? fe : fr;
    } else if (fr.cost < f[o[1]].cost) {
      v[o[2]] = reflected;
      f[o[2]] = fr;
    } else {
      const P contracted = clamp(centroid + 0.5 * (v[o[2]] - centroid));
      const ShapeFit fc = eval(contracted);
      if (fc.cost < f[o[2]].cost) {
        v[o[2]] = contracted;
        f[o[2]] = fc;
      } else {  // shrink towards the best
        for (int k : {o[1], o[2]}) {
          v[k] = 0.5 * (v[k] + v[o[0]]);
          f[k] = eval(v[k]);
        }
      }
    }
    const double spread = (v[o[0]] - v[o[2]]).cwiseAbs().maxCoeff();
    if (spread < 1e-5) break;
  }
  int b = 0;
  for (int k = 1; k < 3; ++k) {
    if (f[k].cost < f[b].cost) b = k;
  }
  out.cost = std::isfinite(f[b].cost) ? f[b].cost : out.cost_zero;  // none admissible
  if (out.cost_zero - out.cost >= options.min_gain * out.cost_zero && !f[b].rho_s.isZero()) {
    out.kept = true;
    out.lobe.rho_s = f[b].rho_s;
    out.lobe.kappa = v[b][0];
    out.lobe.n = std::exp(v[b][1]);
    out.lobe.model = model;
  }
  return out;
}

void SkyLobeOptions::Validate() const {
  if (min_samples < 1) throw Error("sky lobe: min_samples must be >= 1");
  if (max_samples < min_samples) throw Error("sky lobe: max_samples must be >= min_samples");
  if (!(min_gain >= 0 && min_gain <= 1)) throw Error("sky lobe: min_gain must be in [0, 1]");
  if (max_iterations < 1) throw Error("sky lobe: max_iterations must be >= 1");
  if (mirror_samples < 0 || mirror_samples > 4096)
    throw Error("sky lobe: mirror_samples must be 0..4096");
}

namespace {

// Eq. 14's terms of one sample; the pieces reduced to u.n, v.n, u.v and their irradiance
// over sigma.
struct SkyLobeTerm {
  struct Piece {
    double un, uv;
    std::array<double, 3> e;
  };
  LobeModel model = LobeModel::kLafortune;
  double vn = 0;
  std::vector<Piece> pieces;
  std::array<double, 3> r{};

  SkyLobeTerm(const SkyLobeSample& s, LobeModel lobe_model)
      : model(lobe_model), vn(s.to_viewer.dot(s.normal)) {
    for (int c = 0; c < 3; ++c) r[c] = s.residual[c] / s.sigma[c];
    if (!(vn > 0)) return;
    for (const LightPiece& p : s.pieces) {
      const Eigen::Vector3d u = p.to_light.cast<double>();
      const double un = u.dot(s.normal);
      if (!(un > 0)) continue;
      Piece q{un, u.dot(s.to_viewer), {}};
      for (int c = 0; c < 3; ++c) q.e[c] = p.irradiance[c] / s.sigma[c];
      pieces.push_back(q);
    }
  }

  // rho: rho_s per channel; shape: kappa, log n.
  template <typename T>
  bool operator()(const T* rho, const T* shape, T* out) const {
    return Evaluate(model, rho, shape, out);
  }
  template <typename T>
  bool Evaluate(LobeModel lobe_model, const T* rho, const T* shape, T* out) const {
    const T n = exp(shape[1]);
    T sum[3] = {T(0), T(0), T(0)};
    for (const Piece& q : pieces) {
      const T f = LobeShape(lobe_model, shape[0], n, q.un, vn, q.uv);
      for (int c = 0; c < 3; ++c) sum[c] += q.e[c] * f;
    }
    for (int c = 0; c < 3; ++c) out[c] = rho[c] * sum[c] - r[c];
    return true;
  }
};

}  // namespace

ceres::CostFunction* SkyLobeCost(const SkyLobeSample& sample, LobeModel model) {
  return new ceres::AutoDiffCostFunction<SkyLobeTerm, 3, 3, 2>(new SkyLobeTerm(sample, model));
}

struct SkyLobeCosts::Terms {
  std::vector<SkyLobeTerm> terms;
  std::vector<Eigen::Vector3d> diffuse;  // diffuse_se / sigma
};

SkyLobeCosts::SkyLobeCosts(const std::vector<SkyLobeSample>& samples)
    : terms_(std::make_unique<Terms>()) {
  terms_->terms.reserve(samples.size());
  for (const SkyLobeSample& s : samples) {
    terms_->terms.emplace_back(s, LobeModel::kLafortune);  // the model is the lobe's, below
    terms_->diffuse.push_back(s.diffuse_se.cwiseQuotient(s.sigma));
  }
}

SkyLobeCosts::~SkyLobeCosts() = default;

double SkyLobeCosts::Cost(const SpecularLobe& lobe) const {
  const double rho[3] = {lobe.rho_s[0], lobe.rho_s[1], lobe.rho_s[2]};
  const double shape[2] = {lobe.kappa, std::log(lobe.n)};
  double cost = 0;
  for (const SkyLobeTerm& term : terms_->terms) {
    double out[3];
    term.Evaluate(lobe.model, rho, shape, out);
    for (double o : out) cost += o * o;
  }
  return cost;
}

double SkyLobeCosts::CostRefittingDiffuse(const SpecularLobe& lobe) const {
  const double rho[3] = {lobe.rho_s[0], lobe.rho_s[1], lobe.rho_s[2]};
  const double shape[2] = {lobe.kappa, std::log(lobe.n)};
  // Per channel, with z = r - lobe and d the diffuse term (over sigma): sum z^2 - (d.z)^2 / d.d.
  std::array<double, 3> zz{}, dz{}, dd{};
  for (size_t k = 0; k < terms_->terms.size(); ++k) {
    double out[3];
    terms_->terms[k].Evaluate(lobe.model, rho, shape, out);
    for (int c = 0; c < 3; ++c) {
      const double z = -out[c], d = terms_->diffuse[k][c];
      zz[c] += z * z;
      dz[c] += d * z;
      dd[c] += d * d;
    }
  }
  double cost = 0;
  for (int c = 0; c < 3; ++c) cost += zz[c] - (dd[c] > 0 ? dz[c] * dz[c] / dd[c] : 0);
  return std::max(0.0, cost);
}

double SkyLobeCost(const std::vector<SkyLobeSample>& samples, const SpecularLobe& lobe) {
  return SkyLobeCosts(samples).Cost(lobe);
}

double SkyLobeCostRefittingDiffuse(const std::vector<SkyLobeSample>& samples,
                                   const SpecularLobe& lobe) {
  return SkyLobeCosts(samples).CostRefittingDiffuse(lobe);
}

// §4.2.1, eq. 14: Levenberg-Marquardt per block.
LobeFit FitSkyLobe(const std::vector<SkyLobeSample>& all, const SkyLobeOptions& options,
                   const SpecularLobe& start) {
  options.Validate();
  LobeFit out;
  std::vector<const SkyLobeSample*> usable;
  for (const SkyLobeSample& s : all) {
    bool ok = s.residual.allFinite() && s.sigma.allFinite() && s.sigma.minCoeff() > 0 &&
              s.normal.allFinite() && s.to_viewer.allFinite() && !s.pieces.empty();
    for (const LightPiece& p : s.pieces)
      ok = ok && p.to_light.allFinite() && p.irradiance.allFinite();
    if (ok) usable.push_back(&s);
  }
  std::vector<SkyLobeSample> samples;
  const size_t keep = std::min(usable.size(), static_cast<size_t>(options.max_samples));
  for (size_t k = 0; k < keep; ++k) samples.push_back(*usable[(k * usable.size()) / keep]);
  out.samples = static_cast<int>(samples.size());
  const SkyLobeCosts costs(samples);
  out.cost_zero = out.cost = costs.Cost(SpecularLobe{});
  if (options.source == SkyLobeOptions::Source::kSun) {
    if (start.IsZero()) return out;
    // A sun lobe whose reflection of the sky the photographs contradict (eq. 14's cost rises,
    // the diffuse albedos given back the mean reflection they absorbed) is not the material's;
    // with too few samples nothing contradicts it.
    out.cost_zero = costs.CostRefittingDiffuse(SpecularLobe{});
    out.cost = costs.CostRefittingDiffuse(start);
    out.kept = out.samples < options.min_samples || out.cost <= out.cost_zero;
    if (out.kept) out.lobe = start;
    return out;
  }
  if (out.samples < options.min_samples || !(out.cost_zero > 0)) return out;

  const double log_min = std::log(kLobeExponentMin), log_max = std::log(kLobeExponentMax);
  SpecularLobe best;
  double best_cost = out.cost_zero;
  const LobeModel model = start.model;
  const bool microfacet = model == LobeModel::kMicrofacet;
  for (const auto& [kappa0, n0] :
       {std::pair{std::min(start.kappa, 1.0), start.n}, {1.0, 5.0}, {1.0, 80.0}}) {
    double rho[3] = {0.01, 0.01, 0.01};
    double shape[2] = {microfacet ? 1.0 : std::max(kappa0, kLobeKappaMin),
                       std::clamp(std::log(n0), log_min, log_max)};
    ceres::Problem problem;
    for (const SkyLobeSample& s : samples)
      problem.AddResidualBlock(SkyLobeCost(s, model), nullptr, rho, shape);
    for (int c = 0; c < 3; ++c) {
      problem.SetParameterLowerBound(rho, c, 0.0);
      problem.SetParameterUpperBound(rho, c, MaxLobeRho(kLobeExponentMax, model));
    }
    if (microfacet) {
      problem.SetManifold(shape, new ceres::SubsetManifold(2, {0}));  // kappa held at 1
    } else {
      problem.SetParameterLowerBound(shape, 0, kLobeKappaMin);
      problem.SetParameterUpperBound(shape, 0, 1.0);
    }
    problem.SetParameterLowerBound(shape, 1, log_min);
    problem.SetParameterUpperBound(shape, 1, log_max);
    ceres::Solver::Options so;
    so.minimizer_type = ceres::TRUST_REGION;
    so.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
    so.linear_solver_type = ceres::DENSE_QR;
    so.max_num_iterations = options.max_iterations;
    so.num_threads = 2;
    ceres::Solver::Summary summary;
    ceres::Solve(so, &problem, &summary);
    SpecularLobe l;
    l.model = model;
    l.rho_s = Eigen::Vector3d(rho[0], rho[1], rho[2]);
    l.kappa = microfacet ? 1.0 : shape[0];
    l.n = std::exp(shape[1]);
    // The energy bound depends on n: a lobe above it is scaled down to it.
    const double cap = MaxLobeRho(l.n, model);
    if (l.rho_s.maxCoeff() > cap) l.rho_s *= cap / l.rho_s.maxCoeff();
    const double cost = costs.Cost(l);
    if (cost < best_cost && l.rho_s.allFinite()) {
      best = l;
      best_cost = cost;
    }
  }
  out.cost = best_cost;
  if (out.cost_zero - best_cost >= options.min_gain * out.cost_zero && !best.IsZero()) {
    out.kept = true;
    out.lobe = best;
  }
  return out;
}

}  // namespace rouen
