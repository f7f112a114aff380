#include "odomcov/measurement/sequential_test.hpp"

#include <algorithm>
#include <boost/math/distributions/beta.hpp>
#include <cmath>
#include <stdexcept>

namespace odomcov {
namespace {

double log_beta(double a, double b) { return std::lgamma(a) + std::lgamma(b) - std::lgamma(a + b); }

/// The null law of k_j on the k <= states - 1 tracked, from that of k_{j-1} (`from`, after B
/// replicates) when m more are drawn: given k of B, the next m add a beta-binomial(m, k + 1,
/// B - k + 1) number (the posterior of U after k of B is beta(k + 1, B - k + 1)).
std::vector<double> advance(const std::vector<double>& from, std::int64_t B, std::int64_t m) {
  const auto states = static_cast<std::int64_t>(from.size());
  std::vector<double> to(from.size(), 0.0);
  const double lgm = std::lgamma(static_cast<double>(m) + 1);
  for (std::int64_t k = 0; k < states; ++k) {
    if (from[static_cast<std::size_t>(k)] == 0.0) continue;
    const double a = static_cast<double>(k) + 1, b = static_cast<double>(B - k) + 1;
    const double norm = log_beta(a, b);
    for (std::int64_t d = 0; d <= m && k + d < states; ++d) {
      const double dd = static_cast<double>(d), md = static_cast<double>(m - d);
      const double log_p = lgm - std::lgamma(dd + 1) - std::lgamma(md + 1) + log_beta(a + dd, b + md) - norm;
      to[static_cast<std::size_t>(k + d)] += from[static_cast<std::size_t>(k)] * std::exp(log_p);
    }
  }
  return to;
}

}  // namespace

void clopper_pearson(double k, double n, double risk, double out[2]) {
  out[0] = k > 0 ? boost::math::quantile(boost::math::beta_distribution<>(k, n - k + 1), risk / 2) : 0.0;
  out[1] = k < n ? boost::math::quantile(boost::math::beta_distribution<>(k + 1, n - k), 1 - risk / 2) : 1.0;
}

SequentialMcTest::SequentialMcTest(std::vector<std::int64_t> looks, double alpha)
    : looks_(std::move(looks)), alpha_(alpha) {
  if (looks_.empty() || looks_.front() < 1 || !std::is_sorted(looks_.begin(), looks_.end()) ||
      std::adjacent_find(looks_.begin(), looks_.end()) != looks_.end() || !(alpha > 0 && alpha < 1)) {
    throw std::invalid_argument("SequentialMcTest: looks must be increasing and positive, alpha in (0, 1)");
  }
  const double last = static_cast<double>(looks_.back() + 1);
  // A rejection at look j needs (c_j + 1)/(B_j + 1) <= P(k_j <= c_j) <= alpha: k <= alpha (B_J + 1)
  // covers every boundary; one more state for the p-values just beyond.
  states_ = std::min(looks_.back(), static_cast<std::int64_t>(std::floor(alpha * last))) + 2;
  // k_1 is uniform on 0 .. B_1.
  std::vector<double> reached(static_cast<std::size_t>(states_), 0.0);
  for (std::int64_t k = 0; k < states_ && k <= looks_.front(); ++k) {
    reached[static_cast<std::size_t>(k)] = 1.0 / static_cast<double>(looks_.front() + 1);
  }
  double spent = 0.0;
  for (std::size_t j = 0; j < looks_.size(); ++j) {
    if (j > 0) reached = advance(reached, looks_[j - 1], looks_[j] - looks_[j - 1]);
    reached_.push_back(reached);
    // The largest boundary within the spending; the relative 1e-12 lets an exact equality such
    // as 1/400 <= alpha/4 at alpha = 0.01 through despite rounding.
    const double target = alpha * static_cast<double>(looks_[j] + 1) / last * (1 + 1e-12);
    std::int64_t c = -1;
    while (c + 1 < states_ && spent + reached[static_cast<std::size_t>(c + 1)] <= target) {
      spent += reached[static_cast<std::size_t>(c + 1)];
      reached[static_cast<std::size_t>(++c)] = 0.0;  // rejected: no longer going on
    }
    boundary_.push_back(c);
    spent_.push_back(spent);
  }
}

double SequentialMcTest::p_value(std::size_t j, std::int64_t k) const {
  const double before = j > 0 ? spent_[j - 1] : 0.0;
  if (k < 0) return 0.0;
  if (k >= states_) {
    return std::min(1.0, before + static_cast<double>(k + 1) / static_cast<double>(looks_[j] + 1));
  }
  double p = before;
  for (std::int64_t i = 0; i <= k; ++i) p += reached_[j][static_cast<std::size_t>(i)];
  return std::min(1.0, p);
}

std::int64_t SequentialMcTest::critical(std::size_t j) const {
  std::int64_t c = boundary_[j];
  while (c + 1 < states_ && p_value(j, c + 1) <= alpha_ * (1 + 1e-12)) ++c;
  return c;
}

SequentialMcTest::Decision SequentialMcTest::decide(std::size_t j, std::int64_t k, double risk, double level) const {
  if (k <= boundary_[j]) return Decision::reject;
  if (j + 1 == looks_.size()) return Decision::accept;
  double interval[2];
  clopper_pearson(static_cast<double>(k), static_cast<double>(looks_[j]), risk, interval);
  return interval[0] > level ? Decision::accept : Decision::go_on;
}

}  // namespace odomcov
