#include "odomcov/calibration.hpp"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <limits>
#include <nlopt.hpp>

#include "odomcov/error.hpp"
#include "odomcov/format.hpp"
#include "odomcov/propagation.hpp"

namespace odomcov {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

/// One fitted parameter: where it lives in the model and the coordinate the optimiser sees.
struct Handle {
  enum class Kind { k_left, k_right, wheelbase, effect };
  enum class Transform { log, atanh, sqrt, identity };
  std::string name;
  Kind kind = Kind::k_left;
  std::string effect;
  std::size_t index = 0;  // parameter index within the effect
  Transform transform = Transform::log;
  double lower_u = -HUGE_VAL, upper_u = HUGE_VAL;
  double step_u = 0.1;  // BOBYQA's initial step
  double mid = 0.0, half = 1.0;  // atanh: the open interval (mid - half, mid + half)

  double& ref(SuiteModel& m) const {
    switch (kind) {
      case Kind::k_left: return m.robot.noise.k_left;
      case Kind::k_right: return m.robot.noise.k_right;
      case Kind::wheelbase: return m.robot.wheelbase_m;
      case Kind::effect: break;
    }
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

/// Parses "k_left", "wheelbase", "wheel_diameter_ratio.Ed", ... and sets up its coordinate.
Handle make_handle(const std::string& name, const SuiteModel& model) {
  Handle h;
  h.name = name;
  if (name == "k_left" || name == "k_right") {
    h.kind = name == "k_left" ? Handle::Kind::k_left : Handle::Kind::k_right;
    h.transform = Handle::Transform::log;
    h.lower_u = std::log(1e-9);
    h.upper_u = std::log(1.0);
    h.step_u = 0.3;
    return h;
  }
  if (name == "wheelbase") {
    h.kind = Handle::Kind::wheelbase;
    h.transform = Handle::Transform::log;
    h.lower_u = std::log(0.5 * model.robot.wheelbase_m);
    h.upper_u = std::log(2.0 * model.robot.wheelbase_m);
    h.step_u = 0.01;
    return h;
  }
  const std::size_t dot = name.find('.');
  h.kind = Handle::Kind::effect;
  h.effect = name.substr(0, dot);
  const EffectInfo* info = find_effect(h.effect, model.effects);
  const std::string param = name.substr(dot + 1);
  for (std::size_t i = 0; i < info->parameters.size(); ++i) {
    if (info->parameters[i].name == param) h.index = i;
  }
  const EffectParameterInfo& p = info->parameters[h.index];
  const double scale = std::abs(p.typical - p.neutral);
  if (p.lower <= -1e300 && p.upper >= 1e300) {  // signed and unbounded (reference_offset.dx)
    h.transform = Handle::Transform::identity;
    h.lower_u = p.neutral - 1e4 * scale;
    h.upper_u = p.neutral + 1e4 * scale;
    h.step_u = std::max(scale, 1e-6);
  } else if (p.open_lower && p.lower == 0.0) {  // positive scale factors (Ed, Eb, Es)
    h.transform = Handle::Transform::log;
    h.lower_u = std::log(0.5);
    h.upper_u = std::log(2.0);
    h.step_u = std::max(scale, 1e-3);
  } else if (p.open_lower && p.open_upper) {  // an open interval (a, b), e.g. rho in (-1, 1)
    h.transform = Handle::Transform::atanh;
    h.mid = 0.5 * (p.lower + p.upper);
    h.half = 0.5 * (p.upper - p.lower);
    h.lower_u = -6.0;
    h.upper_u = 6.0;
    h.step_u = 0.3;
  } else {  // a size that may be zero (slip, per-run sigma, bump rate and size)
    h.transform = Handle::Transform::sqrt;
    h.lower_u = 0.0;
    h.upper_u = std::sqrt(1e4 * p.typical);
    h.step_u = 0.5 * std::sqrt(p.typical);
  }
  return h;
}

/// Puts the fitted coordinates u into the model.
void apply(SuiteModel& model, const std::vector<Handle>& handles, const double* u) {
  for (std::size_t i = 0; i < handles.size(); ++i) handles[i].ref(model) = handles[i].from_u(u[i]);
}

double likelihood_of(const Suite& suite, const SuiteModel& model, Likelihood kind) {
  const auto res = residuals(suite, model);
  return kind == Likelihood::full ? log_likelihood(res) : scatter_log_likelihood(res);
}

/// Each run's term of the log-likelihood at the coordinates u.
std::vector<double> run_terms(const Suite& suite, SuiteModel& model,
                              const std::vector<Handle>& handles, const double* u,
                              Likelihood kind, std::atomic<std::int64_t>* counter = nullptr) {
  if (counter) ++*counter;
  apply(model, handles, u);
  return run_log_likelihoods(residuals(suite, model), kind == Likelihood::scatter);
}

/// -log L from the runs' terms; 1e300 where it is not finite (a wall for the optimiser).
double negative_sum(const std::vector<double>& terms) {
  double ll = 0.0;
  for (double t : terms) ll += t;
  return std::isfinite(ll) ? -ll : 1e300;
}

double negative_log_likelihood(const Suite& suite, SuiteModel& model,
                               const std::vector<Handle>& handles, const double* u,
                               Likelihood kind, std::atomic<std::int64_t>* counter = nullptr) {
  return negative_sum(run_terms(suite, model, handles, u, kind, counter));
}

}  // namespace

std::string check_fit_parameter(const std::string& name, const EffectList& context) {
  if (name == "k_left" || name == "k_right" || name == "wheelbase") return "";
  const std::size_t dot = name.find('.');
  if (dot == std::string::npos) {
    return "unknown parameter '" + name +
           "' (use k_left, k_right, wheelbase or <effect>.<parameter>)";
  }
  const EffectInfo* info = find_effect(name.substr(0, dot), context);
  if (!info) return "unknown effect in '" + name + "'";
  for (const EffectParameterInfo& p : info->parameters) {
    if (p.name == name.substr(dot + 1)) return "";
  }
  return "effect " + info->name + " has no parameter '" + name.substr(dot + 1) + "'";
}

FitResult fit(const Suite& suite, const SuiteModel& start, const std::vector<std::string>& names,
              Likelihood likelihood, std::atomic<std::int64_t>* evaluations) {
  FitResult out;
  out.names = names;
  out.log_likelihood_before = likelihood_of(suite, start, likelihood);

  // Effects named but absent join the model at their typical size.
  SuiteModel model = start;
  for (const std::string& name : names) {
    const std::size_t dot = name.find('.');
    if (dot == std::string::npos) continue;
    const std::string effect = name.substr(0, dot);
    const bool present = find_spec(model.effects, effect) != nullptr;
    if (!present && find_effect(effect)->grouped) {
      throw EffectError("--params", name + ": add " + effect +
                                        " with the parameter it varies to the model first, e.g. "
                                        "- group_variation: {parameter: wheelbase_error.Eb, sd: 0}");
    }
    if (!present) {
      EffectSpec spec{effect, {}};
      for (const EffectParameterInfo& p : find_effect(effect)->parameters) spec.values.push_back(p.typical);
      model.effects.push_back(spec);
    }
  }
  std::vector<Handle> handles;
  for (const std::string& name : names) handles.push_back(make_handle(name, model));
  const std::size_t n = handles.size();

  std::vector<double> u(n), lower(n), upper(n), step(n);
  for (std::size_t i = 0; i < n; ++i) {
    u[i] = std::clamp(handles[i].to_u(handles[i].ref(model)), handles[i].lower_u, handles[i].upper_u);
    lower[i] = handles[i].lower_u;
    upper[i] = handles[i].upper_u;
    step[i] = handles[i].step_u;
  }
  struct Context {
    const Suite* suite;
    SuiteModel* model;
    const std::vector<Handle>* handles;
    Likelihood kind;
    int evaluations;
    std::atomic<std::int64_t>* counter;
  } context{&suite, &model, &handles, likelihood, 0, evaluations};
  // BOBYQA needs two or more coordinates; one is fitted with the subplex method.
  nlopt::opt opt(n >= 2 ? nlopt::LN_BOBYQA : nlopt::LN_SBPLX, static_cast<unsigned>(n));
  opt.set_lower_bounds(lower);
  opt.set_upper_bounds(upper);
  opt.set_initial_step(step);
  opt.set_xtol_rel(1e-10);
  opt.set_ftol_abs(1e-9);
  opt.set_maxeval(20000);
  opt.set_min_objective(
      [](const std::vector<double>& x, std::vector<double>&, void* data) {
        auto* c = static_cast<Context*>(data);
        ++c->evaluations;
        // No exception may cross NLopt. A custom effect's expression that is not finite at a
        // trial point is a wall for the optimiser; at the start it was an InputError already.
        try {
          return negative_log_likelihood(*c->suite, *c->model, *c->handles, x.data(), c->kind,
                                         c->counter);
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
  best = negative_log_likelihood(suite, model, handles, u.data(), likelihood);
  out.evaluations = context.evaluations;
  out.log_likelihood_after = -best;

  // Observed information in u: two passes of central differences, the second with steps of a
  // fifth of the first pass's standard errors.
  std::vector<double> h(n);
  for (std::size_t i = 0; i < n; ++i) h[i] = 1e-2 * step[i];
  // On the last pass the diagonal's points u +/- h_i also give each run's score by central
  // differences, for the sandwich: the runs' terms there are summed for H and differenced for J.
  Eigen::MatrixXd H(n, n);
  std::vector<std::vector<double>> scores(n);
  for (int pass = 0; pass < 2; ++pass) {
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = i; j < n; ++j) {
        auto terms = [&](double si, double sj) {
          std::vector<double> x = u;
          x[i] += si * h[i];
          x[j] += sj * h[j];
          return run_terms(suite, model, handles, x.data(), likelihood, evaluations);
        };
        auto at = [&](double si, double sj) { return negative_sum(terms(si, sj)); };
        if (i == j) {
          const std::vector<double> up = terms(1, 0), down = terms(-1, 0);
          H(i, i) = (negative_sum(up) - 2 * best + negative_sum(down)) / (h[i] * h[i]);
          scores[i].resize(up.size());
          for (std::size_t r = 0; r < up.size(); ++r) scores[i][r] = (up[r] - down[r]) / (2 * h[i]);
        } else {
          H(i, j) = (at(1, 1) - at(1, -1) - at(-1, 1) + at(-1, -1)) / (4 * h[i] * h[j]);
          H(j, i) = H(i, j);
        }
      }
    }
    if (pass == 0) {
      for (std::size_t i = 0; i < n; ++i) {
        if (H(i, i) > 0) h[i] = std::clamp(0.2 / std::sqrt(H(i, i)), 1e-9, step[i]);
      }
    }
  }
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n));
  for (std::size_t r = 0; r < scores[0].size(); ++r) {
    for (std::size_t i = 0; i < n; ++i) {
      for (std::size_t j = 0; j < n; ++j) {
        J(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) += scores[i][r] * scores[j][r];
      }
    }
  }
  out.values.resize(static_cast<Eigen::Index>(n));
  out.stderrs.setConstant(static_cast<Eigen::Index>(n), kNaN);
  out.robust_stderrs.setConstant(static_cast<Eigen::Index>(n), kNaN);
  out.covariance.setConstant(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n), kNaN);
  Eigen::VectorXd jacobian(n);
  for (std::size_t i = 0; i < n; ++i) {
    out.values(static_cast<Eigen::Index>(i)) = handles[i].from_u(u[i]);
    jacobian(static_cast<Eigen::Index>(i)) = handles[i].dv_du(u[i]);
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(H);
  if (llt.info() == Eigen::Success) {
    const Eigen::MatrixXd cov_u = llt.solve(Eigen::MatrixXd::Identity(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(n)));
    out.covariance = jacobian.asDiagonal() * cov_u * jacobian.asDiagonal();
    const Eigen::MatrixXd robust = jacobian.asDiagonal() * cov_u * J * cov_u * jacobian.asDiagonal();
    for (std::size_t i = 0; i < n; ++i) {
      const auto k = static_cast<Eigen::Index>(i);
      const double se_u = std::sqrt(cov_u(k, k));
      const bool at_bound = (u[i] - lower[i] < 0.5 * se_u) || (upper[i] - u[i] < 0.5 * se_u);
      if (at_bound) {
        out.warnings.push_back(names[i] + " is at its bound (" + format_number(out.values(k)) +
                               "): the data do not determine it; no standard error");
      } else {
        out.stderrs(k) = std::sqrt(out.covariance(k, k));
        out.robust_stderrs(k) = std::sqrt(robust(k, k));
      }
    }
  } else {
    out.warnings.push_back(
        "the information matrix is singular: the data cannot tell these parameters apart "
        "(e.g. bumps.rate and bumps.sigma act only through rate sigma^2); no standard errors");
  }
  // The derivative evaluations above moved the parameters; the result is the optimum.
  apply(model, handles, u.data());
  out.model = model;
  return out;
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
  const double R = (L / 2) / std::sin(r.beta / 2);                           // eq. (8)
  r.Ed = (R + b / 2) / (R - b / 2);                                           // eq. (9)
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
