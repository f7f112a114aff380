// odomcov calibrate SUITE.yaml --out DIR [--candidates FILE] [--holdout SUITE2 | --train REGEX
//   [--test REGEX]] [--rounds N] [--alpha A] [--order 1|2] [--threads T] [--exact] [--json FILE]
//   [--calibration automatic|gaussian|simulation] [--replicates B] [--seed S]
// The whole loop: diagnose, adopt what predicts held-out folds, repeat, joint fit; writes
// DIR/model.yaml, DIR/calibrate.json and DIR/diff_drive.yaml all at once (docs/calibrate.md).
#include <tbb/global_control.h>

#include <csignal>
#include <iostream>
#include <regex>
#include <sstream>

#include "calibrate_command.hpp"
#include "calibrate_output.hpp"
#include "commands.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/io/suite_io.hpp"
#include "odomcov/measurement/calibrate.hpp"
#include "output.hpp"
#include "progress.hpp"
#include "referee_options.hpp"

namespace odomcov::cli {
namespace {

/// --rounds: at least one; more than 100 effects is not a model anyone can read.
constexpr int kMaxRounds = 100;

/// Set by SIGINT: the library stops between two fits and nothing is written.
DiagnoseProgress* g_progress = nullptr;
extern "C" void on_calibrate_interrupt(int) {
  if (g_progress) g_progress->cancel.store(true);
}

void check_options(const CalibrateCliOptions& opt) {
  check_alpha(opt.alpha);
  check_order(opt.order);
  check_threads(opt.threads);
  if (opt.rounds < 1 || opt.rounds > kMaxRounds) {
    throw UsageError("--rounds must be in [1, " + std::to_string(kMaxRounds) + "]");
  }
  if (!opt.test.empty() && opt.train.empty()) throw UsageError("--test needs --train");
  if (!opt.holdout.empty() && !opt.train.empty()) throw UsageError("give --holdout or --train, not both");
  check_output_dir(opt.out);
  if (!opt.json.empty()) check_output_path(opt.json);
}

/// The longest --train/--test pattern: ample for experiment names, and far below the nesting
/// at which std::regex's recursive compiler overflows the stack (about 30 000 parentheses).
constexpr std::size_t kMaxPatternLength = 1000;

/// ECMAScript, matched by libstdc++'s breadth-first (Thompson) executor, whose recursion is
/// bounded by the pattern's automaton. The default, backtracking executor recursed once per
/// character, so a 20 000-character experiment name overflowed the stack, and `(.*)*x` took
/// exponential time. Back-references, the one ECMAScript feature that needs backtracking, are
/// refused (regex_error: error_complexity).
constexpr std::regex::flag_type kPatternSyntax = std::regex::ECMAScript | std::regex_constants::__polynomial;

/// A --train/--test pattern, searched anywhere in a name in one pass: the user's pattern P (first
/// compiled alone, so that only a valid P is accepted) inside `[\s\S]*(?:P)[\s\S]*`, matched
/// against the whole name. That is a search (P's ^ and $ still see the whole name), in time
/// linear in the name; std::regex_search would start the automaton at every character (quadratic:
/// 24 s for `(.*)*x` against a 20 000-character name).
std::regex regex_of(const std::string& option, const std::string& text) {
  if (text.size() > kMaxPatternLength) {
    throw UsageError(option + ": a regular expression of at most " + std::to_string(kMaxPatternLength) +
                     " characters, got " + std::to_string(text.size()));
  }
  try {
    (void)std::regex(text, kPatternSyntax);
    return std::regex("[\\s\\S]*(?:" + text + ")[\\s\\S]*", kPatternSyntax);
  } catch (const std::regex_error& e) {
    throw UsageError(option + ": not a regular expression: " + quote(text) + " (" + e.what() + ")");
  }
}

/// The experiments of `suite` whose names match (`keep`) or do not match `pattern` (regex_of).
Suite select(const Suite& suite, const std::regex& pattern, bool keep) {
  Suite out = suite;
  out.experiments.clear();
  for (const SuiteExperiment& ex : suite.experiments) {
    if (std::regex_match(ex.name, pattern) == keep) out.experiments.push_back(ex);
  }
  return out;
}

/// The training suite and the held-out one (none without --holdout or --train).
CalibrateInputs load_inputs(const CalibrateCliOptions& opt) {
  CalibrateInputs in{load_suite(opt.suite), std::nullopt, {}, {}};
  if (!opt.holdout.empty()) in.held = load_suite(opt.holdout);
  if (opt.train.empty()) return in;
  const Suite all = in.train;
  const std::regex train = regex_of("--train", opt.train);
  in.train = select(all, train, true);
  in.held = opt.test.empty() ? select(all, train, false) : select(all, regex_of("--test", opt.test), true);
  if (in.train.experiments.empty()) throw UsageError("--train " + quote(opt.train) + " matches no experiment of " + opt.suite);
  if (in.held->experiments.empty()) throw UsageError("no experiment of " + opt.suite + " is left to test on");
  return in;
}

std::string number(double v, const char* format = "%.6g") { return format_number(v, format); }

// ---- The report --------------------------------------------------------------------------------

void write_rounds(std::ostream& out, const CalibrateResult& c) {
  out << "Rounds (each adopts the best candidate that predicts its held-out folds better):\n";
  for (std::size_t r = 0; r < c.rounds.size(); ++r) {
    const Diagnosis& d = c.rounds[r];
    out << "  round " << r + 1 << ": ";
    if (!d.best) {
      out << "nothing adopted (NEES mean " << fixed(d.before.nees_mean, 3) << ", " << d.before.verdict << ")\n";
    } else {
      const Candidate& b = d.candidates[*d.best];
      out << b.effect << " (d logL " << fixed(b.delta_log_likelihood, 1) << " in-sample, "
          << (std::isfinite(b.delta_held_out) ? fixed(b.delta_held_out, 1) : std::string("-"))
          << " held out); NEES mean " << fixed(d.before.nees_mean, 3) << " -> " << fixed(d.after.nees_mean, 3) << "\n";
    }
    for (const Candidate& x : d.candidates) {
      if (x.verdict == "adopted" || x.decision.empty()) continue;
      out << "    - " << x.effect << ": " << x.decision << "\n";
    }
  }
  for (const std::string& s : c.simplified) out << "  after the rounds: " << s << "\n";
}

void write_by_kind(std::ostream& out, const NeesByKind& nees, const char* indent = "  ") {
  out << indent << "NEES by kind:";
  for (const auto& [kind, value] : nees) out << " " << kind << " " << fixed(value, 2);
  out << "\n";
}

void write_model(std::ostream& out, const CalibrateResult& c) {
  out << "\nJoint fit of everything named (full likelihood): " << c.joint_note << "\n";
  for (std::size_t i = 0; i < c.joint.names.size(); ++i) {
    const auto k = static_cast<Eigen::Index>(i);
    out << "  " << c.joint.names[i] << " = " << number(c.joint.values(k))
        << (std::isfinite(c.joint.stderrs(k)) ? " +/- " + sci(c.joint.stderrs(k), 2) : std::string(" (no standard error)"))
        << "\n";
  }
  out << "\nThe calibrated model (model.yaml; paste over a suite's robot line and model block):\n"
      << model_yaml(c.model) << "against the training runs: log-likelihood " << fixed(c.after.log_likelihood, 2)
      << ", NEES mean " << fixed(c.after.nees_mean, 3) << ", " << c.after.verdict << "\n";
  write_by_kind(out, c.nees_by_kind);
}

void write_verdict(std::ostream& out, const CalibrateResult& c, double alpha) {
  if (c.explained) {
    out << "\nThe final model is consistent with the training runs (compare at alpha = " << alpha << ").\n";
    return;
  }
  out << "\nThe final model is still inconsistent with the training runs (compare at alpha = " << alpha
      << ", NEES mean " << fixed(c.after.nees_mean, 3) << " against 3): something the candidates do not cover is missing.\n";
  for (const StandIn& s : c.stand_ins) out << "Stand-in: " << s.text << ".\n";
  std::size_t shown = 0;
  for (const ResidualAlignment& a : c.residuals) {
    if (!a.testable || shown == 3 || (shown > 0 && !(a.p_value < alpha))) break;
    out << (shown == 0 ? "The remaining misfit lines up with:\n" : "") << "  " << a.feature
        << " (p = " << format_number(a.p_value, "%.2g") << "): " << a.description << "\n";
    ++shown;
  }
}

void write_predictive(std::ostream& out, const HoldoutSummary::Predictive& p) {
  out << "  each run's marginal NEES (no run conditioned on another): " << fixed(p.plugin_nees_mean, 3)
      << " as the model predicts it; " << fixed(p.sized_nees_mean, 3)
      << " from the training runs' posterior of its parameters and of every absent catalogue effect they size; "
      << fixed(p.nees_mean, 3) << " with those they do not size at their typical sizes besides (a prior, not data)\n";
  write_by_kind(out, p.sized_by_kind, "    from the training posterior: ");
  if (p.parameters.empty()) {
    out << "    no one parameter's exact value would narrow it by " << kPredictiveSpreadShown
        << " NEES: what the training leaves open is in combinations of parameters, each of which the others could "
           "take up\n";
  }
  for (const auto& q : p.parameters) {
    out << "    " << q.name << ": the training runs put it " << sci(q.shift, 2) << " from the model's value, sd "
        << sci(q.posterior_sd, 2)
        << (q.prior_sd > 0 ? " of prior " + sci(q.prior_sd, 2) + (q.sized ? "" : " (the training runs do not size it)")
                           : std::string(" (fitted)"))
        << "; knowing it would narrow the prediction of these runs by " << fixed(q.spread, 2) << " NEES\n";
  }
}

/// The model judged on the held-out runs: compare, the NEES, the refit and the predictive check.
void write_judged_holdout(std::ostream& out, const HoldoutSummary& h) {
  out << "\nHeld-out runs (never seen by the loop): NEES mean " << fixed(h.summary.nees_mean, 3) << ", "
      << h.consistent << " of " << h.experiments << " experiments consistent, " << h.summary.verdict << "\n";
  write_by_kind(out, h.nees_by_kind);
  if (h.refitted) {
    out << "  the same effects fitted on these runs themselves (the best they do having seen them; a prediction "
           "is not expected to do better): NEES mean "
        << fixed(h.refitted->nees_mean, 3) << ", log-likelihood " << fixed(h.refitted->fit.log_likelihood_after, 2)
        << " against " << fixed(h.summary.log_likelihood, 2) << " held out\n";
    write_by_kind(out, h.refitted->nees_by_kind, "    ");
    for (const std::string& p : h.refitted->fit.at_bound) out << "    " << p << " ends at a bound of its range there\n";
  }
  if (h.predictive) write_predictive(out, *h.predictive);
}

void write_holdout(std::ostream& out, const HoldoutSummary& h) {
  if (!h.cannot_predict.empty()) {
    out << "\nHeld-out runs (never seen by the loop): the calibrated model cannot predict them at all, "
           "inconsistent: "
        << h.cannot_predict << "\n";
    out << "  (the model was calibrated and is written; the error above is what it meets on these runs)\n";
  } else {
    write_judged_holdout(out, h);
  }
  if (h.extrapolation.empty()) {
    out << "  every held-out experiment lies inside the training domain\n";
    return;
  }
  out << "  outside the training domain (the model extrapolates):\n";
  for (const std::string& x : h.extrapolation) out << "    " << x << "\n";
}

std::string report(const Suite& suite, const CalibrateResult& c, double alpha) {
  std::ostringstream out;
  std::size_t runs = 0;
  for (const SuiteExperiment& ex : suite.experiments) runs += ex.runs.size();
  out << "odomcov calibrate: " << suite.name << " (" << suite.experiments.size() << " experiments, " << runs
      << " runs), family-wise alpha = " << alpha << " per round\n";
  if (!c.rounds.empty()) out << "cross-validation: " << folds_text(c.rounds.front().folds) << "\n\n";
  write_rounds(out, c);
  write_model(out, c);
  write_verdict(out, c, alpha);
  write_correction(out, c.odometry_correction);
  if (!c.unresolved.empty()) {
    out << "\nNot adopted and not ruled out:";
    for (const std::string& e : c.unresolved) out << (e == c.unresolved.front() ? " " : ", ") << e;
    out << ". The runs do not separate " << (c.unresolved.size() == 1 ? "it" : "them")
        << " from the model's effects; the two blocks below count " << (c.unresolved.size() == 1 ? "its" : "their")
        << " parameters beside the model's, so the next experiment is one that sizes "
        << (c.unresolved.size() == 1 ? "it" : "them") << ".\n";
  }
  out << design_report(c.confounded, c.next_experiments, c.unpredictable_experiments);
  if (c.holdout) write_holdout(out, *c.holdout);
  return out.str();
}

// ---- The files ---------------------------------------------------------------------------------

/// Every file of DIR, written at once (StagedDir: nothing half-written). Ctrl-C waits until
/// the files are in place.
void write_outputs(const CalibrateCliOptions& opt, const Suite& suite, const CalibrateResult& c, const json& doc) {
  StagedDir stage(opt.out);
  stage.write("model.yaml", "# The model odomcov calibrate built from " + suite.name + " (docs/calibrate.md).\n" +
                                model_yaml(c.model));
  stage.write("calibrate.json", doc.dump(1) + "\n");
  stage.write("diff_drive.yaml", diff_drive_yaml(suite, c.diff_drive));
  stage.commit();
  if (!opt.json.empty()) write_json_atomic(opt.json, doc);
}

int run_calibrate(const CalibrateCliOptions& opt) {
  const CalibrateInputs in = prepare_calibrate(opt);
  std::optional<tbb::global_control> threads;
  if (opt.threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, static_cast<std::size_t>(opt.threads));
  DiagnoseProgress progress;
  g_progress = &progress;
  auto previous = std::signal(SIGINT, on_calibrate_interrupt);
  ProgressBar bar([&progress] { return progress.fits_done.load(); },
                  std::function<std::int64_t()>([&progress] { return progress.fits_total.load(); }),
                  [&progress] { return "fits, round " + std::to_string(progress.round.load()); });
  std::optional<CalibrateResult> c;
  try {
    c = calibrate(in.train, in.start, in.options, in.held ? &*in.held : nullptr, &progress);
  } catch (const Cancelled&) {
    bar.finish();
    std::signal(SIGINT, previous);
    std::cerr << "odomcov: interrupted; nothing was written\n";
    return 130;
  }
  bar.finish();
  write_outputs(opt, in.train, *c, calibrate_json(in.train, in.start, *c, opt.alpha,
                                     c->holdout && c->holdout->cannot_predict.empty() ? comparison_json(*in.held, c->holdout->comparison) : json(nullptr)));
  std::signal(SIGINT, previous);
  std::cout << report(in.train, *c, opt.alpha) << "\nWrote " << opt.out << "/model.yaml, calibrate.json and diff_drive.yaml\n";
  return kExitOk;
}

}  // namespace

CLI::App* add_calibrate_options(CLI::App& app, CalibrateCliOptions& opt) {
  CLI::App* cmd = app.add_subcommand("calibrate", "The whole loop: diagnose, adopt what predicts held-out runs, repeat, joint fit");
  cmd->add_option("suite", opt.suite, "Measurement suite (YAML)")->required();
  cmd->add_option("--out", opt.out, "Directory for model.yaml, calibrate.json and diff_drive.yaml")->required();
  cmd->add_option("--candidates", opt.candidates,
                  "YAML list of your own candidate effects (custom, or catalogue ones with starting values)");
  cmd->add_option("--holdout", opt.holdout, "Another suite of runs to judge the final model on");
  cmd->add_option("--train", opt.train, "Calibrate on the experiments whose names match this regular expression");
  cmd->add_option("--test", opt.test, "With --train: judge on the experiments matching this (default: the others)");
  cmd->add_option("--rounds", opt.rounds, "At most this many rounds")->capture_default_str();
  cmd->add_option("--alpha", opt.alpha, "Family-wise significance level over each round's candidates")->capture_default_str();
  cmd->add_option("--order", opt.order, "Model order: 2 (default) = exact Gaussian-heading moments, 1 = first order")
      ->capture_default_str();
  cmd->add_option("--threads", opt.threads, "Worker threads; 0 = all cores")->capture_default_str();
  add_referee_options(cmd, opt.referee);
  cmd->add_option("--json", opt.json, "Also write calibrate.json to this file");
  cmd->add_flag("--exact", opt.exact, "Every fit on the exact path (slow; the reference)");
  return cmd;
}

CalibrateInputs prepare_calibrate(const CalibrateCliOptions& opt) {
  check_options(opt);
  CalibrateInputs in = load_inputs(opt);
  in.options.rounds = opt.rounds;
  in.options.diagnose.alpha = opt.alpha;
  in.options.diagnose.path = opt.exact ? FitPath::exact : FitPath::fast;
  in.options.diagnose.calibration = calibration_options(opt.referee, nullptr);
  in.options.diagnose.candidates = load_candidates(opt.candidates, in.train);
  for (const Suite* s : {&in.train, in.held ? &*in.held : nullptr}) {
    if (s) check_second_order_size(*s, opt.order);
  }
  in.start = suite_model(in.train);
  in.start.order = opt.order;
  check_finite_start(in.train, in.start, "calibration");
  return in;
}

void setup_calibrate(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<CalibrateCliOptions>();
  add_calibrate_options(app, *opt)->callback([opt, &exit_code] { exit_code = run_calibrate(*opt); });
}

}  // namespace odomcov::cli
