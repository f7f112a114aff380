// odomcov sweep SWEEP.yaml [--out CSV] [--shard I/N] [--threads T] [--alpha A] [--order 1|2]
//               [--json FILE]
// One Monte-Carlo validation per grid point, one CSV row each (docs/formats.md, "Sweep file").
#include <algorithm>
#include <cctype>
#include <csignal>
#include <fstream>
#include <iostream>

#include "commands.hpp"
#include "odomcov/base/error.hpp"
#include "odomcov/base/format.hpp"
#include "odomcov/io/sweep.hpp"
#include "output.hpp"
#include "progress.hpp"

namespace odomcov::cli {
namespace {

struct SweepOptions {
  std::string sweep;
  std::string out;
  std::string shard = "1/1";
  int threads = 0;
  double alpha = kDefaultAlpha;
  int order = 1;
  std::string json;
};

/// Set by SIGINT; the running point is cancelled and the rows already written stay valid.
std::atomic<Progress*> g_running{nullptr};
std::atomic<bool> g_interrupted{false};

extern "C" void on_interrupt(int) {
  g_interrupted.store(true);
  if (Progress* p = g_running.load()) p->cancel.store(true);
}

/// True when `text` is one or more decimal digits.
bool all_digits(const std::string& text) {
  return !text.empty() && std::all_of(text.begin(), text.end(), [](unsigned char c) { return std::isdigit(c) != 0; });
}

std::pair<std::size_t, std::size_t> parse_shard(const std::string& text) {
  // Read by hand, not by std::regex: its backtracking matcher recurses once per character and
  // overflowed the stack on a --shard of 100 000 digits.
  const std::size_t slash = text.find('/');
  const std::string first = text.substr(0, slash), second = slash == std::string::npos ? "" : text.substr(slash + 1);
  if (!all_digits(first) || !all_digits(second)) throw UsageError("--shard must be I/N, got " + one_line(text, 100));
  // At most 9 digits each: a longer count cannot be a real shard (and would overflow stoul).
  if (first.size() > 9 || second.size() > 9) {
    throw UsageError("--shard I/N: I and N must be below 1e9, got " + one_line(text, 100));
  }
  const std::size_t i = std::stoul(first), n = std::stoul(second);
  if (n < 1 || i < 1 || i > n) throw UsageError("--shard I/N needs 1 <= I <= N, got " + text);
  return {i, n};
}

std::string csv_row(const SweepPlan& plan, std::size_t point, const Validation& v) {
  const SweepMetrics m = sweep_metrics(v);
  std::string row;
  for (double value : plan.point_values(point)) row += format_number(value) + ",";
  row += std::to_string(v.runs) + "," + std::to_string(v.seed);
  for (double x : {m.std_rel_err.x(), m.std_rel_err.y(), m.std_rel_err.z(), m.max_corr_diff,
                   m.bias_se.x(), m.bias_se.y(), m.bias_se.z(), m.p_mean, m.p_cov, m.nees_mean}) {
    row += "," + format_number(x);
  }
  return row + "," + m.verdict.name() + "\n";
}

int run_sweep(const SweepOptions& opt) {
  const auto [shard, shards] = parse_shard(opt.shard);
  check_alpha(opt.alpha);
  check_threads(opt.threads);
  check_order(opt.order);
  if (!opt.out.empty()) check_output_path(opt.out);
  if (!opt.json.empty()) check_output_path(opt.json);
  const SweepPlan plan = load_sweep(opt.sweep);  // validates every point

  std::vector<std::size_t> points;
  std::vector<Config> configs;
  std::int64_t total_steps = 0;
  for (std::size_t i = 0; i < plan.point_count(); ++i) {
    if (i % shards != shard - 1) continue;
    points.push_back(i);
    configs.push_back(plan.point_config(i));
    total_steps += configs.back().simulation.runs * sample_count(configs.back().path);
  }

  std::string header;
  for (const SweepAxis& a : plan.axes) header += a.name + ",";
  for (std::size_t c = 0; c < sweep_metric_columns().size(); ++c) {
    header += (c ? "," : "") + sweep_metric_columns()[c];
  }
  header += "\n";
  std::ofstream file;
  if (!opt.out.empty()) {
    file.open(opt.out, std::ios::trunc);
    if (!file) throw UsageError("cannot write " + opt.out);
  }
  std::ostream& csv = opt.out.empty() ? std::cout : file;
  csv << header << std::flush;

  Progress progress;
  std::atomic<std::int64_t> steps_done{0};
  std::atomic<std::int64_t> current_samples{0};
  ProgressBar bar(
      [&] { return steps_done.load() + progress.runs_done.load() * current_samples.load(); },
      total_steps, "steps");
  g_running.store(&progress);
  auto previous = std::signal(SIGINT, on_interrupt);

  json rows = json::array();
  std::size_t finished = 0;
  for (std::size_t k = 0; k < points.size() && !g_interrupted.load(); ++k) {
    const Config& config = configs[k];
    progress.runs_done = 0;
    current_samples = sample_count(config.path);
    const Validation v = validate(config, opt.alpha, opt.threads, &progress, 0, opt.order);
    if (g_interrupted.load()) break;  // the cancelled point is incomplete: no row
    csv << csv_row(plan, points[k], v) << std::flush;
    steps_done += config.simulation.runs * current_samples.load();
    ++finished;
    json row = validation_json(config.name, v);
    const std::vector<double> values = plan.point_values(points[k]);
    json axes = json::object();
    for (std::size_t a = 0; a < plan.axes.size(); ++a) axes[plan.axes[a].name] = values[a];
    row["point"] = points[k];
    row["axes"] = axes;
    rows.push_back(row);
  }
  std::signal(SIGINT, previous);
  g_running.store(nullptr);
  bar.finish();

  if (g_interrupted.load()) {
    std::cerr << "odomcov: interrupted after " << finished << " of " << points.size()
              << " points; the rows written are complete\n";
    return 130;
  }
  if (!opt.out.empty()) {
    std::size_t inconsistent = 0;
    for (const json& r : rows) inconsistent += r["verdict"] != "consistent";
    std::cout << "odomcov sweep: " << plan.file << " (base " << plan.base_file << "), shard "
              << shard << "/" << shards << ": " << points.size() << " of " << plan.point_count()
              << " points, " << inconsistent << " inconsistent or untestable at alpha = " << opt.alpha
              << "; rows in " << opt.out << "\n";
  }
  if (!opt.json.empty()) {
    write_json_atomic(opt.json, {{"sweep", plan.file},
                                 {"base", plan.base_file},
                                 {"shard", opt.shard},
                                 {"alpha", opt.alpha},
                                 {"order", opt.order},
                                 {"rows", rows}});
  }
  return kExitOk;
}

}  // namespace

void setup_sweep(CLI::App& app, int& exit_code) {
  auto opt = std::make_shared<SweepOptions>();
  CLI::App* cmd =
      app.add_subcommand("sweep", "Run a grid of Monte-Carlo validations, one CSV row per point");
  cmd->add_option("sweep", opt->sweep, "Sweep file (YAML)")->required();
  cmd->add_option("--out", opt->out, "Write the CSV to this file (default: stdout)");
  cmd->add_option("--shard", opt->shard, "Run only points i with i mod N = I-1 (I/N)")
      ->capture_default_str();
  cmd->add_option("--threads", opt->threads, "Worker threads; 0 = all cores")
      ->capture_default_str();
  cmd->add_option("--alpha", opt->alpha, "Significance level of the tests")
      ->capture_default_str();
  cmd->add_option("--order", opt->order,
                  "Model order of the CSV columns and verdicts (1 or 2); every point's JSON has "
                  "both orders")
      ->capture_default_str();
  cmd->add_option("--json", opt->json, "Also write every point's run JSON to this file");
  cmd->callback([opt, &exit_code] { exit_code = run_sweep(*opt); });
}

}  // namespace odomcov::cli
