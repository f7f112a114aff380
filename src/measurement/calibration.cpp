#include "odomcov/measurement/calibration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <memory>
#include <nlopt.hpp>
#include <optional>
#include <utility>

#include "odomcov/base/error.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/engine/propagation.hpp"

namespace odomcov {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// One fitted parameter: where it lives in the model and the coordinate the optimiser sees.
struct Handle : FitCoordinate {
  using Transform = FitCoordinate::Transform;
  std::string name;
  const RobotParameter* robot = nullptr;  // a robot parameter, else an effect's:
  std::string effect;
  std::size_t index = 0;  // parameter index within the effect
  double neutral_u = std::numeric_limits<double>::quiet_NaN();  // the "no effect" value's u

  double fd_step(double v) const { return std::max(fd_abs, fd_rel * std::abs(v - fd_origin)); }
  double& ref(SuiteModel& m) const {
    if (robot) return robot->ref(m.robot);
    if (EffectSpec* e = find_spec(m.effects, effect)) return e->values[index];
    throw std::logic_error("fit: effect not in the model");
  }
  double to_u(double v) const {
    switch (transform) {
      case Transform::log: return std::log(v);
      case Transform::atanh: return std::atanh((v - mid) / half);
      case Transform::sqrt: return std::sqrt(std::max(v, 0.0));
      case Transform::identity: return v;
    }
    return v;
  }
  double from_u(double u) const {
    switch (transform) {
      case Transform::log: return std::exp(u);
      case Transform::atanh: return mid + half * std::tanh(u);
      case Transform::sqrt: return u * u;
      case Transform::identity: return u;
    }
    return u;
  }
  double dv_du(double u) const {
    switch (transform) {
      case Transform::log: return std::exp(u);
      case Transform::atanh: return half * (1.0 - std::tanh(u) * std::tanh(u));
      case Transform::sqrt: return 2.0 * u;
      case Transform::identity: return 1.0;
    }
    return 1.0;
  }
};

const RobotParameter* find_robot_parameter(const std::string& name) {
  for (const RobotParameter& p : robot_parameters()) {
    if (p.name == name) return &p;
  }
  return nullptr;
}

/// Parses a robot parameter's or "<effect>.<parameter>" and sets up its coordinate (the robot
/// parameter's own, or fit_coordinate from the effect parameter's declared range).
Handle make_handle(const std::string& name, const SuiteModel& model) {
  Handle h;
  if ((h.robot = find_robot_parameter(name))) {
    static_cast<FitCoordinate&>(h) = h.robot->coordinate(model.robot);
    h.name = name;
    return h;
  }
  const std::size_t dot = name.find('.');
  const std::string effect = name.substr(0, dot);
  const EffectInfo* info = find_effect(effect, model.effects);
  const std::string param = name.substr(dot + 1);
  std::size_t index = 0;
  for (std::size_t i = 0; i < info->parameters.size(); ++i) {
    if (info->parameters[i].name == param) index = i;
  }
  static_cast<FitCoordinate&>(h) = fit_coordinate(info->parameters[index]);
  h.neutral_u = h.to_u(info->parameters[index].neutral);
  h.name = name;
  h.effect = effect;
  h.index = index;
  return h;
}

/// Puts the fitted coordinates u into the model.
void apply(SuiteModel& model, const std::vector<Handle>& handles, const double* u) {
  for (std::size_t i = 0; i < handles.size(); ++i) handles[i].ref(model) = handles[i].from_u(u[i]);
}

using Residuals = std::vector<std::vector<RunResidual>>;
/// Each run's term of the log-likelihood at the coordinates u.
using Terms = std::function<std::vector<double>(const std::vector<double>& u)>;

/// `terms` with a model that cannot be computed at u (a custom expression out of its range, order
/// 2 beyond its piece limit as an effect cuts the pieces: an InputError) taken as a wall, every
/// run's term -inf, once a point has been computed (which gives the run count); at the first
/// point the error stands (the start must be computable). The exact path's optimiser already
/// took walls; its last evaluation and the difference points of its information now do too,
/// where a parameter's optimum lies beside one (those standard errors come out NaN).
Terms wall_aware(Terms terms) {
  auto runs = std::make_shared<std::size_t>(0);
  return [terms = std::move(terms), runs](const std::vector<double>& u) {
    try {
      std::vector<double> t = terms(u);
      *runs = t.size();
      return t;
    } catch (const InputError&) {
      if (*runs == 0) throw;
      return std::vector<double>(*runs, -std::numeric_limits<double>::infinity());
    }
  };
}

/// -log L from the runs' terms; 1e300 where it is not finite (a wall for the optimiser).
double negative_sum(const std::vector<double>& terms) {
  double ll = 0.0;
  for (double t : terms) ll += t;
  return std::isfinite(ll) ? -ll : 1e300;
}

/// The optimiser's box in the fitted coordinates.
struct Box {
  std::vector<double> lower, upper, step;
};
Box box_of(const std::vector<Handle>& handles) {
  Box b;
  for (const Handle& h : handles) {
    b.lower.push_back(h.lower_u);
    b.upper.push_back(h.upper_u);
    b.step.push_back(h.step_u);
  }
  return b;
}

/// Minimises -log L over u in the box from u (updated in place) with NLopt: BOBYQA, or the
/// subplex method for one coordinate (BOBYQA needs two or more), until a step changes -log L by
/// less than `ftol_abs`. Returns -log L at u (with no coordinate, NLopt has nothing to do:
/// -log L there).
double minimise(const Terms& terms, std::vector<double>& u, const Box& box, int* evaluations,
                double ftol_abs = 1e-9) {
  if (u.empty()) return negative_sum(terms(u));
  // NLopt refuses a start outside the box, and BOBYQA can return a point an ulp beyond a bound
  // (a square root's upper bound), which the next call would start from.
  const auto into_box = [&] {
    for (std::size_t i = 0; i < u.size(); ++i) u[i] = std::clamp(u[i], box.lower[i], box.upper[i]);
  };
  into_box();
  struct Context {
    const Terms* terms;
    int* evaluations;
  } context{&terms, evaluations};
  nlopt::opt opt(u.size() >= 2 ? nlopt::LN_BOBYQA : nlopt::LN_SBPLX, static_cast<unsigned>(u.size()));
  opt.set_lower_bounds(box.lower);
  opt.set_upper_bounds(box.upper);
  opt.set_initial_step(box.step);
  opt.set_xtol_rel(1e-10);
  opt.set_ftol_abs(ftol_abs);
  opt.set_maxeval(20000);
  opt.set_min_objective(
      [](const std::vector<double>& x, std::vector<double>&, void* data) {
        auto* c = static_cast<Context*>(data);
        if (c->evaluations) ++*c->evaluations;
        // No exception may cross NLopt. A custom effect's expression that is not finite at a
        // trial point is a wall for the optimiser; at the start it was an InputError already.
        try {
          return negative_sum((*c->terms)(x));
        } catch (const InputError&) {
          return 1e300;
        }
      },
      &context);
  double best = 0.0;
  try {
    opt.optimize(u, best);
  } catch (const nlopt::roundoff_limited&) {
    // converged as far as rounding allows; u holds the best point
  }
  into_box();
  return negative_sum(terms(u));
}

/// The observed information H of -log L at u and J, the sum of the runs' score outer products,
/// by central differences in two passes, the second with steps of a fifth of the first pass's
/// standard errors. On the last pass the diagonal's points u +/- h_i also give each run's score,
/// for the sandwich: the runs' terms there are summed for H and differenced for J.
struct Information {
  Eigen::MatrixXd H, J;
};
/// The runs' terms at u moved by si h_i along coordinate i and by sj h_j along j.
std::vector<double> terms_at(const Terms& terms, const std::vector<double>& u, const std::vector<double>& h,
                             std::size_t i, std::size_t j, double si, double sj) {
  std::vector<double> x = u;
  x[i] += si * h[i];
  x[j] += sj * h[j];
  return terms(x);
}

/// One pass of central differences of -log L around u (where it is `best`) with steps h: H,
/// and each run's score per coordinate from the diagonal's points u +/- h_i.
void difference_pass(const Terms& terms, const std::vector<double>& u, double best,
                     const std::vector<double>& h, Eigen::MatrixXd& H,
                     std::vector<std::vector<double>>& scores) {
  const std::size_t n = u.size();
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i; j < n; ++j) {
      auto at = [&](double si, double sj) { return negative_sum(terms_at(terms, u, h, i, j, si, sj)); };
      if (i == j) {
        const std::vector<double> up = terms_at(terms, u, h, i, j, 1, 0), down = terms_at(terms, u, h, i, j, -1, 0);
        H(i, i) = (negative_sum(up) - 2 * best + negative_sum(down)) / (h[i] * h[i]);
        scores[i].resize(up.size());
        for (std::size_t r = 0; r < up.size(); ++r) scores[i][r] = (up[r] - down[r]) / (2 * h[i]);
      } else {
        H(i, j) = (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1)) / (4 * h[i] * h[j]);
        H(j, i) = H(i, j);
      }
    }
  }
}

/// J += the sum over the runs of their score outer products.
void add_score_products(const std::vector<std::vector<double>>& scores, Eigen::MatrixXd& J) {
  const std::size_t n = scores.size();
  for (std::size_t r = 0; r < scores[0].size(); ++r) {
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = 0; j < n; ++j) {
        J(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) += scores[i][r] * scores[j][r];
      }
    }
  }
}

Information information(const Terms& terms, const std::vector<double>& u, double best, const Box& box) {
  const std::size_t n = u.size();
  std::vector<double> h(n);
  for (std::size_t i = 0; i < n; ++i) h[i] = 1e-2 * box.step[i];
  Information info{Eigen::MatrixXd(n, n), Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n))};
  std::vector<std::vector<double>> scores(n);
  difference_pass(terms, u, best, h, info.H, scores);
  // The second pass: steps of a fifth of the first pass's standard errors (within the box's).
  for (std::size_t i = 0; i < n; ++i) {
    if (info.H(i, i) > 0) h[i] = std::clamp(0.2 / std::sqrt(info.H(i, i)), 1e-9, box.step[i]);
  }
  difference_pass(terms, u, best, h, info.H, scores);
  add_score_products(scores, info.J);
  return info;
}

/// True when coordinate u of `h` lies within `within` of a bound of its box that is not the
/// parameter's neutral value (a size at 0 is no effect, not a fit pushed to an edge).
bool at_far_bound(const Handle& h, double u, double within) {
  auto neutral = [&](double bound) { return std::abs(bound - h.neutral_u) <= 1e-12 * std::max(1.0, std::abs(bound)); };
  return (u - h.lower_u < within && !neutral(h.lower_u)) || (h.upper_u - u < within && !neutral(h.upper_u));
}

/// FitResult::rank of an observed information matrix.
int information_rank(const Eigen::MatrixXd& H) {
  const Eigen::Index n = H.rows();
  Eigen::VectorXd scale = Eigen::VectorXd::Zero(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (H(i, i) > 0 && std::isfinite(H(i, i))) scale(i) = 1.0 / std::sqrt(H(i, i));
  }
  const Eigen::MatrixXd unit = scale.asDiagonal() * H * scale.asDiagonal();
  if (!unit.allFinite()) return 0;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(unit, Eigen::EigenvaluesOnly);
  if (eig.info() != Eigen::Success || n == 0) return 0;
  const double largest = eig.eigenvalues().maxCoeff();
  int rank = 0;
  for (Eigen::Index i = 0; i < n; ++i) rank += eig.eigenvalues()(i) > kInformationRankTolerance * largest ? 1 : 0;
  return rank;
}

/// The estimates, their (robust) standard errors and covariance at u from the information.
void fill_estimates(FitResult& out, const std::vector<Handle>& handles, const std::vector<double>& u,
                    const Box& box, const Information& info) {
  const std::size_t n = u.size();
  const auto N = static_cast<Eigen::Index>(n);
  out.values.resize(N);
  out.stderrs.setConstant(N, kNaN);
  out.robust_stderrs.setConstant(N, kNaN);
  out.covariance.setConstant(N, N, kNaN);
  Eigen::VectorXd jacobian(N);
  for (std::size_t i = 0; i < n; ++i) {
    out.values(static_cast<Eigen::Index>(i)) = handles[i].from_u(u[i]);
    jacobian(static_cast<Eigen::Index>(i)) = handles[i].dv_du(u[i]);
  }
  out.rank = information_rank(info.H);
  const Eigen::LLT<Eigen::MatrixXd> llt(info.H);
  if (llt.info() != Eigen::Success) {
    out.warnings.push_back(
        "the information matrix is singular: the data cannot tell these parameters apart "
        "(e.g. a rate and a size that act only through rate x size^2); no standard errors");
    for (std::size_t i = 0; i < n; ++i) {
      if (at_far_bound(handles[i], u[i], 1e-6 * box.step[i])) out.at_bound.push_back(out.names[i]);
    }
    return;
  }
  const Eigen::MatrixXd cov_u = llt.solve(Eigen::MatrixXd::Identity(N, N));
  out.covariance = jacobian.asDiagonal() * cov_u * jacobian.asDiagonal();
  const Eigen::MatrixXd robust = jacobian.asDiagonal() * cov_u * info.J * cov_u * jacobian.asDiagonal();
  for (std::size_t i = 0; i < n; ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    const double se_u = std::sqrt(cov_u(k, k));
    const bool at_bound = (u[i] - box.lower[i] < 0.5 * se_u) || (box.upper[i] - u[i] < 0.5 * se_u);
    if (at_far_bound(handles[i], u[i], 0.5 * se_u)) out.at_bound.push_back(out.names[i]);
    if (at_bound) {
      out.warnings.push_back(out.names[i] + " is at its bound (" + format_number(out.values(k)) +
                             "): the data do not determine it; no standard error");
    } else {
      out.stderrs(k) = std::sqrt(out.covariance(k, k));
      out.robust_stderrs(k) = std::sqrt(robust(k, k));
    }
  }
}

/// Effects named but absent join the model: every parameter at its typical size, or with
/// `neutral_fitted` the fitted ones at their neutral value (the effect then does nothing).
void add_named_effects(SuiteModel& model, const std::vector<std::string>& names, bool neutral_fitted) {
  for (const std::string& name : names) {
    const std::size_t dot = name.find('.');
    if (dot == std::string::npos) continue;
    const std::string effect = name.substr(0, dot);
    if (find_spec(model.effects, effect)) continue;
    if (find_effect(effect)->grouped) {
      throw EffectError("--params", name + ": add " + effect +
                                        " with the parameter it varies to the model first, e.g. "
                                        "- group_variation: {parameter: wheelbase_error.Eb, sd: 0}");
    }
    EffectSpec spec{effect, {}};
    for (const EffectParameterInfo& p : find_effect(effect)->parameters) {
      const bool fitted = std::find(names.begin(), names.end(), effect + "." + p.name) != names.end();
      spec.values.push_back(neutral_fitted && fitted ? p.neutral : p.typical);
    }
    model.effects.push_back(spec);
  }
}

/// The start in the fitted coordinates (the model's values, clamped into the box).
std::vector<double> start_coordinates(SuiteModel& model, const std::vector<Handle>& handles) {
  std::vector<double> u;
  for (const Handle& h : handles) u.push_back(std::clamp(h.to_u(h.ref(model)), h.lower_u, h.upper_u));
  return u;
}

/// Residuals of a model, computed for the fit: the whole suite's, or a cache view's.
using Evaluate = std::function<Residuals(const SuiteModel&)>;

FitResult fit_exact(const Evaluate& evaluate, SuiteModel model, const std::vector<Handle>& handles,
                    Likelihood kind, std::atomic<std::int64_t>* counter, FitResult out) {
  const Terms terms = wall_aware([&](const std::vector<double>& u) {
    if (counter) ++*counter;
    apply(model, handles, u.data());
    return run_log_likelihoods(evaluate(model), kind == Likelihood::scatter);
  });
  const Box box = box_of(handles);
  std::vector<double> u = start_coordinates(model, handles);
  const double best = minimise(terms, u, box, &out.evaluations);
  out.log_likelihood_after = -best;
  fill_estimates(out, handles, u, box, information(terms, u, best, box));
  // The derivative evaluations above moved the parameters; the result is the optimum.
  apply(model, handles, u.data());
  out.model = model;
  return out;
}

// ---- The fast path ----------------------------------------------------------------------------

/// What a run contributes to the likelihood: its residual d = error - mean, covariance S and
/// group columns u, u2 (group_variation; zero without), as one vector (d, S column by column, u,
/// u2).
using RunVector = Eigen::Matrix<double, 18, 1>;

/// Every run's residual and covariance as a quadratic in the offsets delta of the fitted values
/// from the anchor's:
///   y(delta) = y0 + sum_k (g_k delta_k + c_k delta_k^2 / 2) + sum_{k<l} x_kl delta_k delta_l,
/// with g_k, c_k from two exact points on parameter k's axis and x_kl from one point off both.
/// The exact model is matched at all these points, and in slope and curvature at the anchor up
/// to the differences' error.
class Surrogate {
 public:
  Surrogate(const Residuals& anchor, std::vector<double> values)
      : v0_(std::move(values)), buffer_(anchor) {  // the buffer keeps each run's group
    for (const auto& ex : anchor) {
      sizes_.push_back(ex.size());
      for (const RunResidual& r : ex) y0_.push_back(to_vector(r));
    }
    const std::size_t n = v0_.size();
    slope_.assign(n, {});
    curvature_.assign(n, {});
    first_.assign(n, {});
    first_offset_.assign(n, 0.0);
  }

  /// Parameter k's slope and curvature from its values at offsets o1 and o2.
  void set_axis(std::size_t k, double o1, const Residuals& f1, double o2, const Residuals& f2) {
    const double det = 0.5 * o1 * o2 * (o2 - o1);
    const std::vector<RunVector> y1 = flat(f1), y2 = flat(f2);
    slope_[k].resize(y0_.size());
    curvature_[k].resize(y0_.size());
    for (std::size_t i = 0; i < y0_.size(); ++i) {
      const RunVector d1 = y1[i] - y0_[i], d2 = y2[i] - y0_[i];
      slope_[k][i] = (0.5 * o2 * o2 * d1 - 0.5 * o1 * o1 * d2) / det;
      curvature_[k][i] = (o1 * d2 - o2 * d1) / det;
    }
    first_[k] = y1;
    first_offset_[k] = o1;
  }

  /// Parameter k's slope from one point at offset o, its curvature (and every cross term) taken
  /// from `near`, a surrogate anchored close by: the curvature changes by the third derivative
  /// times the distance, so the slope's error is that times o/2.
  void set_axis_from(std::size_t k, double o, const Residuals& f, const Surrogate& near) {
    const std::vector<RunVector> y = flat(f);
    curvature_[k] = near.curvature_[k];
    slope_[k].resize(y0_.size());
    for (std::size_t i = 0; i < y0_.size(); ++i) {
      slope_[k][i] = (y[i] - y0_[i]) / o - 0.5 * o * curvature_[k][i];
    }
    pairs_ = near.pairs_;
  }

  /// The cross term of k and l from the value at both their first offsets (set_axis first).
  void set_pair(std::size_t k, std::size_t l, const Residuals& f) {
    const std::vector<RunVector> y = flat(f);
    Pair p{k, l, std::vector<RunVector>(y0_.size())};
    for (std::size_t i = 0; i < y0_.size(); ++i) {
      p.cross[i] = (y[i] - first_[k][i] - first_[l][i] + y0_[i]) / (first_offset_[k] * first_offset_[l]);
    }
    pairs_.push_back(std::move(p));
  }

  /// Each run's term of the log-likelihood at the values v.
  std::vector<double> terms(const std::vector<double>& v, Likelihood kind) const {
    std::vector<double> delta(v.size());
    for (std::size_t k = 0; k < v.size(); ++k) delta[k] = v[k] - v0_[k];
    std::size_t i = 0;
    for (auto& ex : buffer_) {
      for (RunResidual& r : ex) {
        RunVector y = y0_[i];
        for (std::size_t k = 0; k < delta.size(); ++k) {
          y += delta[k] * (slope_[k][i] + 0.5 * delta[k] * curvature_[k][i]);
        }
        for (const Pair& p : pairs_) y += delta[p.k] * delta[p.l] * p.cross[i];
        r.error = y.head<3>();
        r.mean.setZero();
        const Matrix3 S = Eigen::Map<const Matrix3>(y.data() + 3);
        r.cov = 0.5 * (S + S.transpose());
        r.group_column = y.segment<3>(12);
        r.group_column2 = y.tail<3>();
        ++i;
      }
    }
    return run_log_likelihoods(buffer_, kind == Likelihood::scatter);
  }

 private:
  struct Pair {
    std::size_t k, l;
    std::vector<RunVector> cross;
  };
  static RunVector to_vector(const RunResidual& r) {
    RunVector y;
    y.head<3>() = r.error - r.mean;
    y.segment<9>(3) = Eigen::Map<const Eigen::Matrix<double, 9, 1>>(r.cov.data());
    y.segment<3>(12) = r.group_column;
    y.tail<3>() = r.group_column2;
    return y;
  }
  static std::vector<RunVector> flat(const Residuals& res) {
    std::vector<RunVector> out;
    for (const auto& ex : res) {
      for (const RunResidual& r : ex) out.push_back(to_vector(r));
    }
    return out;
  }
  std::vector<double> v0_;
  std::vector<std::size_t> sizes_;
  std::vector<RunVector> y0_;
  std::vector<std::vector<RunVector>> slope_, curvature_, first_;
  std::vector<double> first_offset_;
  std::vector<Pair> pairs_;
  mutable Residuals buffer_;
};

/// The residuals of `model`, or nullptr where a custom expression is not finite (or leaves its
/// range) there: a wall, as for the optimiser.
const Residuals* residuals_or_wall(ResidualCache& cache, const SuiteModel& model, std::atomic<std::int64_t>* counter) {
  try {
    return &cache.at(model, counter);
  } catch (const InputError&) {
    return nullptr;
  }
}

/// The pairs of offsets of parameter k's difference points from v, preferred first: +-h when
/// both are inside its range, then h and 2h, then -h and -2h (away from a bound, or from a wall
/// a custom expression meets on one side).
std::vector<std::pair<double, double>> axis_offsets(const Handle& h, double v) {
  const double step = h.fd_step(v);
  const double lo = h.from_u(h.lower_u), hi = h.from_u(h.upper_u);
  auto inside = [&](double x) { return x >= lo && x <= hi; };
  std::vector<std::pair<double, double>> out;
  if (inside(v - step) && inside(v + step)) out.emplace_back(-step, step);
  if (inside(v + 2 * step)) out.emplace_back(step, 2 * step);
  if (inside(v - 2 * step) || out.empty()) out.emplace_back(-step, -2 * step);
  return out;
}

/// A re-anchor takes the previous anchor's curvatures only when that anchor's surrogate foretold
/// the exact log-likelihood at the new one within this: else the model is not quadratic over
/// the step (a candidate that lands far from its neutral start), and its curvatures are taken
/// afresh.
constexpr double kCurvatureTrust = 1.0;

/// The residuals of `model` with parameters `offsets` (index, offset from v) moved, or nullptr
/// at a wall.
const Residuals* residuals_moved(const SuiteModel& model, const std::vector<Handle>& handles,
                                 const std::vector<double>& v,
                                 std::initializer_list<std::pair<std::size_t, double>> offsets,
                                 ResidualCache& cache, std::atomic<std::int64_t>* counter) {
  SuiteModel m = model;
  for (const auto& [k, o] : offsets) handles[k].ref(m) = v[k] + o;
  return residuals_or_wall(cache, m, counter);
}

/// Parameter k's axis of the surrogate s at v from the first pair of difference points that no
/// wall blocks (on a re-anchor one point, curvatures from `near`); its first point's offset, or
/// NaN when walls block every pair.
double set_axis_clear_of_walls(Surrogate& s, const SuiteModel& model, const std::vector<Handle>& handles,
                               const std::vector<double>& v, std::size_t k, ResidualCache& cache,
                               std::atomic<std::int64_t>* counter, const Surrogate* near) {
  double tried = 0.0;
  for (const auto& [o1, o2] : axis_offsets(handles[k], v[k])) {
    if (near) {
      const double o = o2 > 0 ? handles[k].fd_step(v[k]) : -handles[k].fd_step(v[k]);
      if (o == tried) continue;  // the pairs h, 2h and -h, h share the point h
      tried = o;
      if (const Residuals* f = residuals_moved(model, handles, v, {{k, o}}, cache, counter)) {
        s.set_axis_from(k, o, *f, *near);
        return o;
      }
      continue;
    }
    // The cache's entries stay where they are: f1 outlives the next evaluation.
    const Residuals* f1 = residuals_moved(model, handles, v, {{k, o1}}, cache, counter);
    const Residuals* f2 = f1 ? residuals_moved(model, handles, v, {{k, o2}}, cache, counter) : nullptr;
    if (f2) {
      s.set_axis(k, o1, *f1, o2, *f2);
      return o1;
    }
  }
  return std::numeric_limits<double>::quiet_NaN();
}

/// The surrogate at the values v (model holds them): the anchor, two points per parameter and
/// one per pair, all from the cache (a re-anchor: one point per parameter, curvatures from the
/// previous anchor `near`). Empty when walls of custom expressions block every side of a
/// parameter there.
std::optional<Surrogate> anchor_at(const SuiteModel& model, const std::vector<Handle>& handles,
                                   const std::vector<double>& v, ResidualCache& cache,
                                   std::atomic<std::int64_t>* counter, const Surrogate* near = nullptr) {
  const Residuals* anchor = residuals_or_wall(cache, model, counter);
  if (!anchor) return std::nullopt;
  Surrogate s(*anchor, v);
  std::vector<double> first(handles.size());
  for (std::size_t k = 0; k < handles.size(); ++k) {
    first[k] = set_axis_clear_of_walls(s, model, handles, v, k, cache, counter, near);
    if (std::isnan(first[k])) return std::nullopt;
  }
  for (std::size_t k = 0; !near && k < handles.size(); ++k) {
    for (std::size_t l = k + 1; l < handles.size(); ++l) {
      const Residuals* f = residuals_moved(model, handles, v, {{k, first[k]}, {l, first[l]}}, cache, counter);
      if (!f) return std::nullopt;
      s.set_pair(k, l, *f);
    }
  }
  return s;
}

/// Linearise -> optimise -> re-anchor exactly, until the exact log-likelihood stops improving.
FitResult fit_fast(SuiteModel model, const std::vector<Handle>& handles,
                   Likelihood kind, std::atomic<std::int64_t>* counter, ResidualCache& cache,
                   FitResult out) {
  constexpr int kMaxAnchors = 20, kMaxHalvings = 6;
  const std::int64_t computed_before = cache.computed();
  const bool scatter = kind == Likelihood::scatter;
  const Box box = box_of(handles);
  std::vector<double> u = start_coordinates(model, handles);
  auto values = [&](const std::vector<double>& x) {
    std::vector<double> v(x.size());
    for (std::size_t k = 0; k < x.size(); ++k) v[k] = handles[k].from_u(x[k]);
    return v;
  };
  auto exact = [&](const std::vector<double>& x) {
    apply(model, handles, x.data());
    const Residuals* r = residuals_or_wall(cache, model, counter);
    return r ? -negative_sum(run_log_likelihoods(*r, scatter)) : -1e300;  // a wall for the optimiser
  };
  double ll = exact(u);
  apply(model, handles, u.data());
  std::optional<Surrogate> start = anchor_at(model, handles, values(u), cache, counter);
  if (!start) {  // walled off at the start: the exact path, whose optimiser takes walls
    FitResult exact_fit = fit_exact([&](const SuiteModel& m) { return cache.evaluate(m); }, model, handles,
                                    kind, counter, std::move(out));
    exact_fit.evaluations = static_cast<int>(cache.computed() - computed_before);
    exact_fit.verified = true;
    return exact_fit;
  }
  Surrogate s = std::move(*start);
  Terms surrogate = [&](const std::vector<double>& x) { return s.terms(values(x), kind); };
  out.verified = false;
  for (out.anchors = 1; out.anchors <= kMaxAnchors; ++out.anchors) {
    std::vector<double> p = u;
    const double predicted = -minimise(surrogate, p, box, nullptr);
    if (!(predicted - ll > kFitTolerance)) {  // the anchor is the surrogate's optimum
      out.verified = true;
      break;
    }
    double ll_p = exact(p);
    int halvings = 0;
    for (; halvings < kMaxHalvings && !(ll_p > ll); ++halvings) {
      for (std::size_t k = 0; k < p.size(); ++k) p[k] = 0.5 * (p[k] + u[k]);
      ll_p = exact(p);
    }
    if (!(ll_p > ll)) break;  // no step improves: the anchor stands
    const double gain = ll_p - ll;
    const bool matched = std::abs(ll_p - predicted) < kFitTolerance;  // full step, as foreseen
    out.verified = matched && halvings == 0;
    u = p;
    ll = ll_p;
    // The exact log-likelihood stopped improving, or the surrogate foresaw the exact one at its
    // optimum: re-anchoring there would gain no more than the surrogate's error.
    if (gain < kFitTolerance || matched) break;
    apply(model, handles, u.data());
    const bool trusted = std::abs(ll_p - predicted) < kCurvatureTrust;
    std::optional<Surrogate> next = anchor_at(model, handles, values(u), cache, counter, trusted ? &s : nullptr);
    if (!next) break;  // a wall beside the new point: it stands, unverified (refit_exactly takes walls)
    s = std::move(*next);
  }
  out.anchors = std::min(out.anchors, kMaxAnchors);
  out.log_likelihood_after = ll;
  fill_estimates(out, handles, u, box, information(surrogate, u, negative_sum(surrogate(u)), box));
  apply(model, handles, u.data());
  out.model = model;
  out.evaluations = static_cast<int>(cache.computed() - computed_before);
  return out;
}

/// What a key tells apart: every number of the model (its residuals), or only those that move
/// the robot (residuals' `predictions`: the measurement noise, the measurement-only effects and
/// the grouped ones, group_variation, enter after the prediction).
enum class KeyOf { residuals, predictions };

/// The cache key of a model: its numbers, bit for bit, with inert catalogue effects (all values
/// neutral) left out. A custom effect is never left out: its "neutral" values are the start
/// its author gave (EffectInfo of a custom effect), which need not do nothing.
std::string model_key(const SuiteModel& m, KeyOf of = KeyOf::residuals) {
  std::string key;
  auto put = [&key](double x) { key.append(reinterpret_cast<const char*>(&x), sizeof x); };
  Robot robot = m.robot;  // every robot parameter, bit for bit
  for (const RobotParameter& p : robot_parameters()) put(p.ref(robot));
  if (of == KeyOf::residuals) {
    put(m.measurement_noise.xy_m);
    put(m.measurement_noise.theta_rad);
  }
  put(m.order);
  for (const EffectSpec& e : m.effects) {
    const EffectInfo* info = info_of(e);
    bool inert = info && !e.custom && info->parameters.size() == e.values.size();
    for (std::size_t i = 0; inert && i < e.values.size(); ++i) inert = e.values[i] == info->parameters[i].neutral;
    if (inert || (of == KeyOf::predictions && enters_after_prediction(e))) continue;
    key += e.name;
    key += '\0';
    key += e.target;  // group_variation's varied parameter
    key += '\0';
    // A custom definition is immutable and shared by every copy of its spec: its address
    // identifies it (two definitions of one name never meet in one model).
    const auto definition = reinterpret_cast<std::uintptr_t>(e.custom.get());
    key.append(reinterpret_cast<const char*>(&definition), sizeof definition);
    for (double v : e.values) put(v);
  }
  return key;
}

}  // namespace

/// What a cache and its views share: the suite and every model's residuals, each propagated
/// once.
struct ResidualCache::Store {
  template <class T>
  struct Entry {
    T value;
    std::int64_t used;  // the generation that last read it
  };
  /// The entry of `key` in `map`, computed by `make` when absent; marked as used now.
  template <class T, class Make>
  T& get(std::map<std::string, Entry<T>>& map, const std::string& key, Make make) {
    auto it = map.find(key);
    if (it == map.end()) it = map.emplace(key, Entry<T>{make(), generation}).first;
    it->second.used = generation;
    return it->second.value;
  }
  /// A model's residuals, filled in experiment by experiment as requests need them.
  struct Partial {
    Residuals value;
    std::vector<bool> have;
  };
  /// The residuals of `model` (its model_key) with at least the experiments `need` marks
  /// (nullptr: every one) computed; only the missing ones are propagated. A fold's fit asks for
  /// its training experiments, its held-out score for the rest: together one propagation of
  /// the suite. (residuals: the marked experiments get the same numbers as a whole propagation.)
  const Residuals& residuals_of(const SuiteModel& model, const std::string& key, const std::vector<bool>* need,
                                std::atomic<std::int64_t>* counter) {
    const std::size_t n = suite->experiments.size();
    auto it = by_model.find(key);
    if (it == by_model.end()) {
      it = by_model.emplace(key, Entry<Partial>{{Residuals(n), std::vector<bool>(n, false)}, generation}).first;
    }
    it->second.used = generation;
    Partial& p = it->second.value;
    std::vector<bool> missing(n, false);
    bool any = false;
    for (std::size_t e = 0; e < n; ++e) {
      missing[e] = (need == nullptr || (*need)[e]) && !p.have[e];
      any = any || missing[e];
    }
    if (any) {
      if (counter) ++*counter;
      ++computed;
      RunPredictions& kept = get(predictions, model_key(model, KeyOf::predictions), [] { return RunPredictions(); });
      Residuals fresh = residuals(*suite, model, &coarse, &missing, &kept);
      for (std::size_t e = 0; e < n; ++e) {
        if (!missing[e]) continue;
        p.value[e] = std::move(fresh[e]);
        p.have[e] = true;
      }
    }
    return p.value;
  }
  const Suite* suite;
  CoarseRuns coarse;  // the logged runs' coarse pieces, made once for every model
  std::map<std::string, Entry<Partial>> by_model;
  /// Each run's prediction, by model_key(KeyOf::predictions): models that differ only in a
  /// reference offset, a group's sd or the measurement noise share them.
  std::map<std::string, Entry<RunPredictions>> predictions;
  std::map<std::string, Entry<Comparison>> comparisons;  // by model, alpha and the referee's options
  std::int64_t computed = 0;
  std::int64_t generation = 0;
};

ResidualCache::ResidualCache(const Suite& suite)
    : store_(std::make_shared<Store>(Store{&suite, coarsen_logged_runs(suite), {}, {}, {}, 0, 0})) {}

void ResidualCache::age() {
  auto drop_unused = [this](auto& map) {
    for (auto it = map.begin(); it != map.end();) {
      it = it->second.used < store_->generation ? map.erase(it) : std::next(it);
    }
  };
  drop_unused(store_->by_model);
  drop_unused(store_->predictions);
  drop_unused(store_->comparisons);
  ++store_->generation;
}

ResidualCache::ResidualCache(ResidualCache& parent, std::vector<bool> keep)
    : store_(parent.store_), keep_(std::move(keep)) {
  if (keep_.size() != store_->suite->experiments.size()) {
    throw std::invalid_argument("ResidualCache: one flag per experiment of the suite");
  }
}

const Suite& ResidualCache::suite() const { return *store_->suite; }

std::int64_t ResidualCache::computed() const { return store_->computed; }

std::vector<std::vector<RunResidual>> ResidualCache::evaluate(const SuiteModel& model) {
  ++store_->computed;
  if (keep_.empty()) return residuals(*store_->suite, model, &store_->coarse);
  return select_experiments(residuals(*store_->suite, model, &store_->coarse, &keep_), keep_);
}

const std::vector<std::vector<RunResidual>>& ResidualCache::full(const SuiteModel& model,
                                                                 std::atomic<std::int64_t>* counter) {
  return store_->residuals_of(model, model_key(model), nullptr, counter);
}

const std::vector<std::vector<RunResidual>>& ResidualCache::at(const SuiteModel& model,
                                                               std::atomic<std::int64_t>* counter) {
  if (keep_.empty()) return full(model, counter);
  const std::string key = model_key(model);
  auto it = subsets_.find(key);
  if (it != subsets_.end()) return it->second;
  return subsets_.emplace(key, select_experiments(store_->residuals_of(model, key, &keep_, counter), keep_))
      .first->second;
}

const Comparison& ResidualCache::comparison(const SuiteModel& model, double alpha,
                                             const CalibrationOptions& options) {
  std::string key = model_key(model);
  auto put = [&key](auto x) { key.append(reinterpret_cast<const char*>(&x), sizeof x); };
  put(alpha);
  put(options.method);
  put(options.max_replicates);
  put(options.seed);
  if (model.domain) {  // the verdict names the experiments outside it
    for (const Domain::Range& r : {model.domain->speed_mps, model.domain->spin_fraction, model.domain->length_m,
                                   model.domain->duration_s}) {
      put(r.lo);
      put(r.hi);
    }
  }
  return store_->get(store_->comparisons, key, [&] { return compare(*store_->suite, model, alpha, full(model), options); });
}

std::vector<std::vector<RunResidual>> select_experiments(
    const std::vector<std::vector<RunResidual>>& residuals, const std::vector<bool>& keep) {
  std::vector<std::vector<RunResidual>> out;
  for (std::size_t e = 0; e < residuals.size() && e < keep.size(); ++e) {
    if (keep[e]) out.push_back(residuals[e]);
  }
  return out;
}

namespace {

/// The spec of `effects` that the fit name "<effect>.<parameter>" names, and the parameter's
/// index in it; spec nullptr when there is none.
template <class List>  // EffectList, or const EffectList
auto locate_parameter(List& effects, const std::string& name) -> std::pair<decltype(find_spec(effects, name)), std::size_t> {
  const std::size_t dot = name.find('.');
  auto* spec = dot == std::string::npos ? nullptr : find_spec(effects, name.substr(0, dot));
  const EffectInfo* info = spec ? info_of(*spec) : nullptr;
  for (std::size_t i = 0; info && i < info->parameters.size() && i < spec->values.size(); ++i) {
    if (info->parameters[i].name == name.substr(dot + 1)) return {spec, i};
  }
  return {nullptr, 0};
}

}  // namespace

double& fitted_parameter(SuiteModel& model, const std::string& name) {
  if (const RobotParameter* p = find_robot_parameter(name)) return p->ref(model.robot);
  const auto [spec, i] = locate_parameter(model.effects, name);
  if (!spec) throw std::invalid_argument("fitted_parameter: the model has no " + name);
  return spec->values[i];
}

const EffectParameterInfo* effect_parameter_info(const SuiteModel& model, const std::string& name) {
  const auto [spec, i] = locate_parameter(model.effects, name);
  return spec ? &info_of(*spec)->parameters[i] : nullptr;
}

std::string check_fit_parameter(const std::string& name, const EffectList& context) {
  if (find_robot_parameter(name)) return "";
  const std::size_t dot = name.find('.');
  if (dot == std::string::npos) {
    std::string names;
    for (const RobotParameter& p : robot_parameters()) names += (names.empty() ? "" : ", ") + p.name;
    return "unknown parameter '" + name + "' (use " + names + " or <effect>.<parameter>)";
  }
  const EffectInfo* info = find_effect(name.substr(0, dot), context);
  if (!info) return "unknown effect in '" + name + "'";
  for (const EffectParameterInfo& p : info->parameters) {
    if (p.name == name.substr(dot + 1)) return "";
  }
  return "effect " + info->name + " has no parameter '" + name.substr(dot + 1) + "'";
}

FitResult fit(const Suite& suite, const SuiteModel& start, const std::vector<std::string>& names,
              Likelihood likelihood, std::atomic<std::int64_t>* evaluations, FitPath path,
              ResidualCache* cache) {
  FitResult out;
  out.names = names;
  SuiteModel model = start;
  add_named_effects(model, names, path == FitPath::fast && cache != nullptr);
  std::vector<Handle> handles;
  for (const std::string& name : names) handles.push_back(make_handle(name, model));
  if (path == FitPath::exact) {
    // A cache view (a fold's training runs) is fitted on its own experiments.
    const Evaluate evaluate = [&](const SuiteModel& m) { return cache ? cache->evaluate(m) : residuals(suite, m); };
    const Residuals before = evaluate(start);
    out.log_likelihood_before = likelihood == Likelihood::full ? log_likelihood(before) : scatter_log_likelihood(before);
    return fit_exact(evaluate, model, handles, likelihood, evaluations, std::move(out));
  }
  ResidualCache own(suite);
  ResidualCache& used = cache ? *cache : own;
  const Residuals& before = used.at(start, evaluations);
  out.log_likelihood_before = likelihood == Likelihood::full ? log_likelihood(before) : scatter_log_likelihood(before);
  return fit_fast(model, handles, likelihood, evaluations, used, std::move(out));
}

FitResult refit_exactly(const FitResult& fast, const std::vector<std::string>& own,
                        Likelihood likelihood, std::atomic<std::int64_t>* evaluations,
                        ResidualCache& cache) {
  if (fast.verified) return fast;
  const std::int64_t computed_before = cache.computed();
  const bool scatter = likelihood == Likelihood::scatter;
  SuiteModel model = fast.model;
  std::vector<Handle> handles;
  for (const std::string& name : own) handles.push_back(make_handle(name, model));
  const Terms terms = wall_aware([&](const std::vector<double>& u) {
    if (evaluations) ++*evaluations;
    apply(model, handles, u.data());
    return run_log_likelihoods(cache.evaluate(model), scatter);
  });
  std::vector<double> u = start_coordinates(model, handles);
  const double best = -minimise(terms, u, box_of(handles), nullptr, 0.1 * kFitTolerance);
  apply(model, handles, u.data());
  if (!(best > fast.log_likelihood_after + kFitTolerance)) {
    FitResult out = fast;
    out.verified = true;  // no exact step from its optimum gains: it stands
    out.evaluations += static_cast<int>(cache.computed() - computed_before);
    return out;
  }
  // A better optimum: every parameter again by the fast path from there (the others move with
  // the new values; standard errors at the new optimum).
  std::vector<Handle> all;
  for (const std::string& name : fast.names) all.push_back(make_handle(name, model));
  FitResult out;
  out.names = fast.names;
  out.log_likelihood_before = fast.log_likelihood_before;
  out = fit_fast(model, all, likelihood, evaluations, cache, std::move(out));
  out.evaluations = fast.evaluations + static_cast<int>(cache.computed() - computed_before);
  return out;
}

FitResult refit_exactly_from_both(const FitResult& fast, const SuiteModel& start, const std::vector<std::string>& own,
                                  Likelihood likelihood, std::atomic<std::int64_t>* evaluations, ResidualCache& cache) {
  FitResult from_fast = refit_exactly(fast, own, likelihood, evaluations, cache);
  FitResult at_start = fast;  // the same fit, moved to the start: any exact optimum beats it
  at_start.model = start;
  at_start.verified = false;
  at_start.log_likelihood_after = -std::numeric_limits<double>::infinity();
  FitResult from_start = refit_exactly(at_start, own, likelihood, evaluations, cache);
  return from_start.log_likelihood_after > from_fast.log_likelihood_after + kFitTolerance ? from_start : from_fast;
}

namespace {

/// The experiments named in a comma-separated list.
std::vector<const SuiteExperiment*> experiments_named(const Suite& suite, const std::string& list,
                                                      const std::string& option) {
  std::vector<const SuiteExperiment*> out;
  std::size_t start = 0;
  while (start <= list.size()) {
    const std::size_t comma = list.find(',', start);
    const std::string name = list.substr(start, comma - start);
    const SuiteExperiment* found = nullptr;
    for (const SuiteExperiment& e : suite.experiments) found = e.name == name ? &e : found;
    if (!found) throw InputError(suite.file, 0, option, "no experiment named '" + name + "'");
    out.push_back(found);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
  return out;
}

struct SquareRuns {
  std::vector<Vector3> measured;
  std::vector<std::vector<ArcSegment>> pieces;
  double turned = 0.0;  // mean total encoder heading change
  double side = 0.0;    // longest planned line (path experiments only)
  bool logged = false;
};

SquareRuns square_runs(const std::vector<const SuiteExperiment*>& list, double wheelbase_m) {
  SquareRuns out;
  for (const SuiteExperiment* ex : list) {
    out.logged = out.logged || ex->logged;
    for (std::size_t i = 0; !ex->logged && i < ex->path.interval_count(); ++i) {
      const ArcSegment seg = ex->path.interval(i);
      if (seg.left_m == seg.right_m) out.side = std::max(out.side, std::abs(seg.center_m()));
    }
    for (const SuiteRun& run : ex->runs) {
      out.measured.push_back(run.measured);
      out.pieces.push_back(encoder_pieces(*ex, run));
      for (const ArcSegment& p : out.pieces.back()) out.turned += p.heading_change_rad(wheelbase_m);
    }
  }
  out.turned /= static_cast<double>(out.measured.size());
  return out;
}

/// Centre of gravity of the x-y errors with the odometry re-integrated at (c_L, c_R, b).
Eigen::Vector2d centre_of_gravity(const SquareRuns& runs, double c_left, double c_right,
                                  double wheelbase_m) {
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  for (std::size_t r = 0; r < runs.measured.size(); ++r) {
    Vector3 odometry = Vector3::Zero();
    for (const ArcSegment& p : runs.pieces[r]) {
      odometry = drive(odometry, {c_left * p.left_m, c_right * p.right_m}, wheelbase_m);
    }
    sum += (runs.measured[r] - odometry).head<2>();
  }
  return sum / static_cast<double>(runs.measured.size());
}

}  // namespace

UmbmarkResult umbmark(const Suite& suite, const std::string& cw, const std::string& ccw,
                      std::optional<double> side_m) {
  const double b = suite.robot.wheelbase_m;
  const std::vector<const SuiteExperiment*> squares_cw = experiments_named(suite, cw, "--cw");
  const std::vector<const SuiteExperiment*> squares_ccw = experiments_named(suite, ccw, "--ccw");
  const SquareRuns runs_cw = square_runs(squares_cw, b);
  const SquareRuns runs_ccw = square_runs(squares_ccw, b);
  if (runs_cw.turned > -M_PI) {
    throw InputError(suite.file, 0, "--cw", "these runs turn " + format_number(runs_cw.turned, "%.3f") +
                                                " rad in all; a clockwise square turns about -2 pi");
  }
  if (runs_ccw.turned < M_PI) {
    throw InputError(suite.file, 0, "--ccw", "these runs turn " + format_number(runs_ccw.turned, "%.3f") +
                                                 " rad in all; a counter-clockwise square turns about +2 pi");
  }
  UmbmarkResult r;
  r.runs_cw = static_cast<std::int64_t>(runs_cw.measured.size());
  r.runs_ccw = static_cast<std::int64_t>(runs_ccw.measured.size());
  // The side: given, or the planned paths' line length.
  if (!side_m && (runs_cw.logged || runs_ccw.logged)) {
    throw InputError(suite.file, 0, "--side",
                     "logged runs do not tell the square's side; give it with --side");
  }
  r.side_m = side_m ? *side_m : std::max(runs_cw.side, runs_ccw.side);
  if (!(r.side_m > 0)) throw InputError(suite.file, 0, "--side", "the square's side must be > 0");
  const double L = r.side_m;
  r.cg_cw = centre_of_gravity(runs_cw, 1.0, 1.0, b);
  r.cg_ccw = centre_of_gravity(runs_ccw, 1.0, 1.0, b);
  const double x_cw = r.cg_cw.x(), y_cw = r.cg_cw.y(), x_ccw = r.cg_ccw.x(), y_ccw = r.cg_ccw.y();
  r.alpha = 0.5 * ((x_cw + x_ccw) / (-4 * L) + (y_cw - y_ccw) / (-4 * L));  // [Chong97] eq. (6)
  r.beta = 0.5 * ((x_cw - x_ccw) / (-4 * L) + (y_cw + y_ccw) / (-4 * L));   // eq. (7)
  // Eq. (9) with R = (L/2)/sin(beta/2) (eq. 8) divided through by R, so that beta = 0 (no
  // curvature: R infinite) gives Ed = 1 instead of inf/inf.
  const double q = (b / L) * std::sin(r.beta / 2);                            // (b/2)/R
  r.Ed = (1 + q) / (1 - q);                                                   // eq. (9)
  r.Eb = (M_PI / 2) / (M_PI / 2 - r.alpha);                                   // eq. (10)
  r.c_left = 2 / (r.Ed + 1);                                                  // eq. (11)
  r.c_right = 2 / (1 / r.Ed + 1);
  r.wheelbase_corrected = r.Eb * b;
  r.emax_before = std::max(r.cg_cw.norm(), r.cg_ccw.norm());                 // eq. (12)
  r.cg_cw_after = centre_of_gravity(runs_cw, r.c_left, r.c_right, r.wheelbase_corrected);
  r.cg_ccw_after = centre_of_gravity(runs_ccw, r.c_left, r.c_right, r.wheelbase_corrected);
  r.emax_after = std::max(r.cg_cw_after.norm(), r.cg_ccw_after.norm());

  // The cross-check: Ed and Eb by maximum likelihood on the same runs with the full model (no
  // small angles, no turns on the spot), and the Emax,sys its corrections leave.
  Suite squares = suite;
  squares.experiments.clear();
  for (const auto* list : {&squares_cw, &squares_ccw}) {
    for (const SuiteExperiment* e : *list) squares.experiments.push_back(*e);
  }
  const FitResult ml = fit(squares, suite_model(squares),
                           {"wheel_diameter_ratio.Ed", "wheelbase_error.Eb"});
  r.ml_Ed = ml.values(0);
  r.ml_Eb = ml.values(1);
  r.ml_Ed_stderr = ml.stderrs(0);
  r.ml_Eb_stderr = ml.stderrs(1);
  const double ml_left = 2 / (r.ml_Ed + 1), ml_right = 2 / (1 / r.ml_Ed + 1);
  r.ml_emax_after = std::max(centre_of_gravity(runs_cw, ml_left, ml_right, r.ml_Eb * b).norm(),
                             centre_of_gravity(runs_ccw, ml_left, ml_right, r.ml_Eb * b).norm());
  return r;
}

}  // namespace odomcov
