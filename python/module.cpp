// The odomcov Python module (pybind11). NumPy arrays in and out; dicts shaped like the CLI's
// JSON (docs/library.md). Frames and units as everywhere in odomcov (docs/conventions.md).
#include <pybind11/eigen.h>

#include <cmath>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "odomcov/measurement/calibrate.hpp"
#include "odomcov/measurement/calibration.hpp"
#include "odomcov/measurement/comparison.hpp"
#include "odomcov/measurement/config.hpp"
#include "odomcov/measurement/diagnosis.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/closed_form/odometry_covariance.hpp"
#include "odomcov/engine/propagation.hpp"
#include "odomcov/engine/simulator.hpp"
#include "odomcov/engine/statistics.hpp"
#include "odomcov/measurement/suite.hpp"
#include "odomcov/measurement/validation.hpp"
#include "odomcov/io/config_io.hpp"
#include "odomcov/io/suite_io.hpp"
#include "calibrate_output.hpp"  // src/cli: diagnose's and calibrate's JSON, as the CLI writes it
#include "failures.hpp"          // src/cli: the failures in words

namespace py = pybind11;
using namespace odomcov;

namespace {

using Array = py::array_t<double, py::array::c_style | py::array::forcecast>;

/// [{"wheel_diameter_ratio": {"Ed": 1.004}}, {"custom": {...}}, ...] -> EffectList: written as
/// JSON (a subset of YAML) and read by the configs' own parser, so catalogue, group_variation
/// and custom effects take the same checks and give the same errors (as ValueError).
EffectList effects_from_python(const py::object& obj) {
  if (obj.is_none()) return {};
  const std::string text = py::str(py::module_::import("json").attr("dumps")(obj));
  return parse_effect_list(text, "effects");
}

/// N x 3 x 3 array from a list of matrices.
template <class Get>
Array stack3x3(std::size_t n, Get get) {
  Array out({static_cast<py::ssize_t>(n), py::ssize_t{3}, py::ssize_t{3}});
  auto a = out.mutable_unchecked<3>();
  for (std::size_t i = 0; i < n; ++i) {
    const Matrix3 m = get(i);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) a(static_cast<py::ssize_t>(i), r, c) = m(r, c);
  }
  return out;
}
template <class Get>
Array stack3(std::size_t n, Get get) {
  Array out({static_cast<py::ssize_t>(n), py::ssize_t{3}});
  auto a = out.mutable_unchecked<2>();
  for (std::size_t i = 0; i < n; ++i) {
    const Vector3 v = get(i);
    for (int c = 0; c < 3; ++c) a(static_cast<py::ssize_t>(i), c) = v(c);
  }
  return out;
}

py::dict predict_py(const Array& left, const Array& right, double wheelbase, double k_left,
                    double k_right, const py::object& effects, const py::object& t, double heading0) {
  if (left.ndim() != 1 || right.ndim() != 1 || left.size() != right.size() || left.size() < 1) {
    throw py::value_error("left and right must be 1-D arrays of the same length >= 1");
  }
  if (!(wheelbase > 0)) throw py::value_error("wheelbase must be > 0");
  if (!(k_left >= 0) || !(k_right >= 0)) throw py::value_error("k_left and k_right must be >= 0");
  if (!std::isfinite(heading0)) throw py::value_error("heading0 must be finite");
  const auto l = left.unchecked<1>();
  const auto r = right.unchecked<1>();
  const std::size_t n = static_cast<std::size_t>(left.size());
  std::vector<ArcSegment> pieces;
  pieces.reserve(n);
  for (std::size_t i = 1; i < n; ++i) {
    const auto j = static_cast<py::ssize_t>(i);
    pieces.push_back({l(j) - l(j - 1), r(j) - r(j - 1)});
  }
  // Each piece's duration from the sample times, when given (speed- and time-dependent effects).
  std::vector<double> durations;
  if (!t.is_none()) {
    const Array times = t.cast<Array>();
    if (times.ndim() != 1 || times.size() != left.size()) throw py::value_error("t must be a 1-D array as long as left");
    const auto ts = times.unchecked<1>();
    for (py::ssize_t j = 1; j < times.size(); ++j) {
      if (!(ts(j) > ts(j - 1))) throw py::value_error("t must increase strictly (t[" + std::to_string(j) + "])");
      durations.push_back(ts(j) - ts(j - 1));
    }
  }
  const Robot robot{wheelbase, {k_left, k_right}};
  const EffectList list = effects_from_python(effects);
  py::dict out;
  if (list.empty()) {  // the closed form, step by step
    std::vector<Vector3> pose(n, Vector3::Zero());
    std::vector<Matrix3> cov(n, Matrix3::Zero());
    OdometryCovariance odo(wheelbase, robot.noise);
    for (std::size_t i = 1; i < n; ++i) {
      const OdometryStep& s = odo.step(pieces[i - 1]);
      pose[i] = s.pose_world;
      cov[i] = s.P_world;
    }
    out["pose"] = stack3(n, [&](std::size_t i) { return pose[i]; });
    out["cov"] = stack3x3(n, [&](std::size_t i) { return cov[i]; });
    out["mean"] = stack3(n, [](std::size_t) { return Vector3::Zero().eval(); });
  } else {  // the propagation engine with the model's effects
    const std::vector<Prediction> p = predict_trajectory(pieces, durations, robot, list, heading0);
    out["pose"] = stack3(n, [&](std::size_t i) { return p[i].odometry_end_pose; });
    out["cov"] = stack3x3(n, [&](std::size_t i) { return p[i].cov; });  // exactly symmetric
    out["mean"] = stack3(n, [&](std::size_t i) { return p[i].mean; });
  }
  return out;
}

py::dict moments_dict(const SampleMoments& m) {
  py::dict d;
  d["n"] = m.n;
  d["mean"] = m.mean;
  d["cov"] = m.cov;
  return d;
}
py::dict test_dict(const TestResult& t) {
  py::dict d;
  d["statistic"] = t.statistic;
  d["dof"] = t.dof;
  d["p_value"] = t.p_value;
  d["valid"] = t.valid;
  return d;
}

py::dict theory_py(const std::string& config_file) {
  const Config config = load_config(config_file);
  const PathCovariance t = path_covariance(config.path, config.robot);
  py::list keyframes;
  for (const KeyframeCovariance& k : t.keyframes) {
    py::dict d;
    d["t"] = k.t_s;
    d["pose"] = k.pose_world;
    d["cov"] = k.P_world;
    d["segment_cov"] = k.segment_P_world;
    keyframes.append(d);
  }
  py::dict out;
  out["name"] = config.name;
  out["wheelbase"] = config.robot.wheelbase_m;
  out["k_left"] = config.robot.noise.k_left;
  out["k_right"] = config.robot.noise.k_right;
  out["keyframes"] = keyframes;
  Array kf({static_cast<py::ssize_t>(config.path.keyframes.size()), py::ssize_t{3}});
  for (std::size_t i = 0; i < config.path.keyframes.size(); ++i) {
    const Keyframe& k = config.path.keyframes[i];
    kf.mutable_at(i, 0) = k.t_s, kf.mutable_at(i, 1) = k.left_m, kf.mutable_at(i, 2) = k.right_m;
  }
  out["path"] = kf;  // (t, cumulative left, cumulative right) per keyframe
  return out;
}

py::dict simulate_py(const std::string& config_file, std::optional<std::int64_t> runs,
                     std::optional<std::uint64_t> seed, int threads, bool errors) {
  if (threads < 0) throw py::value_error("threads must be >= 0 (0 = all cores)");
  Config config = load_config(config_file);
  if (runs) config.simulation.runs = *runs;
  if (seed) config.simulation.seed = *seed;
  check_simulation_size(config_file, 0, "runs", config.simulation.runs, sample_count(config.path));
  const Simulator sim(config.world_robot(), config.path, config.world.effects);
  py::dict out;
  out["runs"] = config.simulation.runs;
  out["seed"] = config.simulation.seed;
  out["odometry_end_pose"] = sim.odometry_end_pose();
  if (errors) {
    std::vector<Vector3> e;
    {
      py::gil_scoped_release release;
      e = sim.errors(config.simulation.seed, 0, config.simulation.runs, threads);
    }
    out["errors"] = stack3(e.size(), [&](std::size_t i) { return e[i]; });
    const SampleMoments m = moments(e);
    out["mean"] = m.mean;
    out["cov"] = m.cov;
  } else {
    MomentAccumulator acc;
    {
      py::gil_scoped_release release;
      acc = sim.simulate(config.simulation.runs, config.simulation.seed, threads);
    }
    const SampleMoments m = moments(acc);
    out["mean"] = m.mean;
    out["cov"] = m.cov;
  }
  return out;
}

py::dict compare_py(const Suite& suite, double alpha) {
  Comparison c;
  {
    py::gil_scoped_release release;
    c = compare(suite, suite_model(suite), alpha);
  }
  py::list experiments;
  for (const ExperimentComparison& e : c.experiments) {
    py::dict d;
    d["name"] = e.name;
    d["n"] = e.n;
    d["measured"] = moments_dict(e.measured);
    py::dict predicted;
    predicted["mean"] = e.predicted_mean;
    predicted["cov"] = e.predicted_cov;
    d["predicted"] = predicted;
    py::dict tests;
    tests["mean"] = test_dict(e.mean_test);
    tests["covariance"] = test_dict(e.cov_test);
    d["tests"] = tests;
    d["nees_mean"] = e.nees_mean;
    d["outside_95"] = e.outside_95;
    d["log_likelihood"] = e.log_likelihood;
    d["verdict"] = e.verdict.name();
    d["errors"] = stack3(e.errors.size(), [&](std::size_t i) { return e.errors[i]; });
    experiments.append(d);
  }
  py::dict out;
  out["alpha"] = c.alpha;
  out["experiments"] = experiments;
  out["kurtosis"] = test_dict(c.kurtosis);
  out["log_likelihood"] = c.log_likelihood;
  out["verdict"] = c.verdict.name();
  out["failures"] = cli::failure_texts(c);
  return out;
}

py::dict fit_py(const Suite& suite, const std::vector<std::string>& params) {
  for (const std::string& p : params) {
    const std::string problem = check_fit_parameter(p);
    if (!problem.empty()) throw py::value_error(problem);
  }
  FitResult r;
  {
    py::gil_scoped_release release;
    r = fit(suite, suite_model(suite), params);
  }
  py::dict values, stderrs, robust;
  for (std::size_t i = 0; i < r.names.size(); ++i) {
    const auto j = static_cast<Eigen::Index>(i);
    values[r.names[i].c_str()] = r.values(j);
    stderrs[r.names[i].c_str()] = r.stderrs(j);
    robust[r.names[i].c_str()] = r.robust_stderrs(j);
  }
  py::dict out;
  out["parameters"] = values;
  out["stderr"] = stderrs;
  out["stderr_robust"] = robust;
  out["covariance"] = r.covariance;
  out["log_likelihood_before"] = r.log_likelihood_before;
  out["log_likelihood_after"] = r.log_likelihood_after;
  out["warnings"] = r.warnings;
  out["yaml"] = model_yaml(r.model);
  return out;
}

/// A JSON document of the command line as Python objects (dicts, lists, numbers, None).
py::object to_python(const nlohmann::json& doc) { return py::module_::import("json").attr("loads")(doc.dump()); }

py::object diagnose_py(const Suite& suite, double alpha, const std::vector<std::string>& only) {
  Diagnosis dg;
  {
    py::gil_scoped_release release;
    dg = diagnose(suite, suite_model(suite), alpha, only);
  }
  return to_python(cli::diagnosis_json(suite, suite_model(suite), dg));
}

py::object calibrate_py(const Suite& suite, double alpha, int rounds, const py::object& holdout,
                        const py::object& candidates, int order) {
  if (rounds < 1) throw py::value_error("rounds must be at least 1");
  if (order != 1 && order != 2) throw py::value_error("order must be 1 or 2");
  if (!(alpha > 0 && alpha < 1)) throw py::value_error("alpha must be in (0, 1)");
  CalibrateOptions options;
  options.rounds = rounds;
  options.diagnose.alpha = alpha;
  options.diagnose.candidates = effects_from_python(candidates);
  SuiteModel start = suite_model(suite);
  start.order = order;
  const Suite* held = holdout.is_none() ? nullptr : &holdout.cast<const Suite&>();
  CalibrateResult c;
  {
    py::gil_scoped_release release;
    c = calibrate(suite, start, options, held);
  }
  py::object out = to_python(cli::calibrate_json(suite, start, c, alpha));
  out["diff_drive_yaml"] = cli::diff_drive_yaml(suite, c.diff_drive);
  return out;
}

}  // namespace

PYBIND11_MODULE(_odomcov, m) {
  m.doc() = "odomcov: closed-form covariance of two-wheel odometry, its Monte-Carlo check, and "
            "model-against-measurement tools (docs/library.md)";
  py::register_exception<InputError>(m, "InputError", PyExc_ValueError);

  m.def("predict", &predict_py, py::arg("left"), py::arg("right"), py::arg("wheelbase"),
        py::arg("k_left"), py::arg("k_right"), py::arg("effects") = py::none(), py::arg("t") = py::none(),
        py::arg("heading0") = 0.0,
        R"(Pose and first-order covariance along an encoder log.

left, right: cumulative wheel travel [m] per sample, arrays of length N starting at 0.
wheelbase [m], k_left, k_right [m^(1/2)]: the robot. effects: optional model effects, as a
config's effects list: [{"wheel_diameter_ratio": {"Ed": 1.004}}, {"custom": {...}}, ...].
t: optional sample times [s], length N, strictly increasing: effects that depend on the speed
(v), the time (t) or the acceleration (a) need them. heading0: the run's start heading in the
reference's frame [rad], which custom effects' `heading` starts from (default 0).
Returns {"pose": (N, 3) odometry poses (x, y, theta) in the start frame, "cov": (N, 3, 3)
covariance of the error true - odometry in the start (world) frame, "mean": (N, 3) the
effects' systematic mean error}. Without effects this is the closed form [Kleeman95] per
sample; with them, the propagation engine.)");

  py::class_<OdometryStep>(m, "OdometryStep")
      .def_readonly("pose", &OdometryStep::pose_world)
      .def_readonly("cov", &OdometryStep::P_world)
      .def_readonly("Q", &OdometryStep::Q_world)
      .def_readonly("J_out_in", &OdometryStep::J_out_in)
      .def_readonly("J_out_wheels", &OdometryStep::J_out_wheels);
  py::class_<OdometryCovariance>(m, "OdometryCovariance",
                                 "Stateful closed form: step(left, right) per piece of encoder travel.")
      .def(py::init([](double wheelbase, double k_left, double k_right, const Vector3& pose,
                       const Matrix3& cov) {
             return OdometryCovariance(wheelbase, {k_left, k_right}, pose, cov);
           }),
           py::arg("wheelbase"), py::arg("k_left"), py::arg("k_right"),
           py::arg("pose") = Vector3::Zero().eval(), py::arg("cov") = Matrix3::Zero().eval())
      .def("step", [](OdometryCovariance& o, double left, double right) { return o.step({left, right}); },
           py::arg("left"), py::arg("right"),
           "Drive one constant-curvature piece (wheel travel [m]); returns an OdometryStep with "
           "pose, cov, Q (this step's noise) and the Jacobians J_out_in, J_out_wheels (world frame).")
      .def_property_readonly("pose", &OdometryCovariance::pose_world)
      .def_property_readonly("cov", &OdometryCovariance::P_world);

  m.def("arc_displacement", &arc_displacement, py::arg("center"), py::arg("angle"),
        "End pose of an arc in its start frame [Chong97 eq. (13)]: (d sinc a, d (1-cos a)/a, a).");
  m.def("arc_transition", &arc_transition, py::arg("center"), py::arg("angle"),
        "Phi of [Kleeman95 eq. (36)] (tangential frames), = Ad(T^-1) of the arc's displacement T.");
  m.def("arc_covariance",
        [](double left, double right, double wheelbase, double k_left, double k_right) {
          return arc_covariance({left, right}, wheelbase, {k_left, k_right});
        },
        py::arg("left"), py::arg("right"), py::arg("wheelbase"), py::arg("k_left"), py::arg("k_right"),
        "Q of one segment [Kleeman95 eq. (40)-(41), errata], tangential frame at its end.");
  m.def("tangential_to_world", &tangential_to_world, py::arg("cov_tangential"), py::arg("heading"),
        "T(theta) P T(theta)^T [Kleeman95 eq. (43), erratum 5].");
  m.def("theory", &theory_py, py::arg("config"),
        "The closed form at every keyframe of a path config: like `odomcov theory --json`.");
  m.def("simulate", &simulate_py, py::arg("config"), py::arg("runs") = py::none(),
        py::arg("seed") = py::none(), py::arg("threads") = 0, py::arg("errors") = false,
        "Monte-Carlo of a path config's world: mean and covariance of the end-pose error (and "
        "every run's error with errors=True). Same seed, same numbers for any thread count.");

  py::class_<Suite>(m, "Suite", "A measurement suite, loaded and validated.")
      .def_readonly("name", &Suite::name)
      .def_readonly("file", &Suite::file)
      .def_property_readonly("experiments", [](const Suite& s) {
        std::vector<std::string> names;
        for (const auto& e : s.experiments) names.push_back(e.name);
        return names;
      })
      .def_property_readonly("wheelbase", [](const Suite& s) { return s.robot.wheelbase_m; });
  m.def("load_suite", &load_suite, py::arg("path"), "Read a suite.yaml and every file it names.");
  m.def("compare", &compare_py, py::arg("suite"), py::arg("alpha") = kDefaultAlpha,
        "The suite's model against its runs, like `odomcov compare --json` (errors included).");
  m.def("fit", &fit_py, py::arg("suite"), py::arg("params"),
        "Maximum-likelihood fit of the named parameters, like `odomcov fit --json`.");
  m.def("diagnose", &diagnose_py, py::arg("suite"), py::arg("alpha") = kDiagnoseAlpha,
        py::arg("effects") = std::vector<std::string>{},
        "Which effect is the model missing? `odomcov diagnose --json`'s document.");
  m.def("calibrate", &calibrate_py, py::arg("suite"), py::arg("alpha") = kDiagnoseAlpha,
        py::arg("rounds") = kCalibrateRounds, py::arg("holdout") = py::none(),
        py::arg("candidates") = py::none(), py::arg("order") = 2,
        R"(The whole loop, like `odomcov calibrate`: its calibrate.json as a dict, plus
"diff_drive_yaml" (the text of diff_drive.yaml). holdout: another Suite to judge the final
model on; candidates: your own hypotheses, as `predict`'s effects (custom ones with their
starting values).)");
}
