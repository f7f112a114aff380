// The referee's looks as a group-sequential Monte-Carlo test (docs/diagnose.md, "How many
// replicates"). A statistic T that is a fixed function of one set of errors (the data's or a
// replicate's) is computed for the data and for replicates drawn in blocks; after B_j replicates
// (look j) k_j counts the replicates with T at or below the data's. Under the null the data and
// the replicates are i.i.d., so given the data's U = P(T <= T_data), uniform, every replicate
// counts with probability U independently: k_1 is uniform on 0..B_1 and each next block adds a
// beta-binomial number (a Polya urn). That law is exact whatever the statistic and the
// dependence between the tests inside it, so the rejection boundary of each look can be
// computed: an alpha-spending design [Lan83] in the style of [Besag91]'s sequential Monte-Carlo
// tests, whose probability of ever rejecting a correct model is at most alpha.
#pragma once

#include <cstdint>
#include <vector>

namespace odomcov {

/// Clopper-Pearson interval of a binomial proportion, k of n, at level 1 - risk.
void clopper_pearson(double k, double n, double risk, double out[2]);

class SequentialMcTest {
 public:
  /// `looks`: B_1 < B_2 < ... < B_J replicates. The boundary c_j of look j is the largest for
  /// which the null probability of rejecting at look j or before, the spending, is at most
  /// alpha (B_j + 1)/(B_J + 1): alpha in proportion to the replicates drawn, all of it by the
  /// last look (linear spending, [Lan83]).
  SequentialMcTest(std::vector<std::int64_t> looks, double alpha);

  const std::vector<std::int64_t>& looks() const { return looks_; }
  double alpha() const { return alpha_; }
  /// c_j: reject at look j when k_j <= c_j; -1 when look j cannot reject.
  std::int64_t boundary(std::size_t j) const { return boundary_[j]; }
  /// The null probability of a rejection at look j or before, had no look stopped for
  /// acceptance: at most alpha at the last look.
  double spent(std::size_t j) const { return spent_[j]; }
  /// The stagewise p-value [Tsiatis84] of stopping at look j with k replicates at or below the
  /// data: the null probability of rejecting at an earlier look or of reaching look j with k_j
  /// <= k. It is a valid p-value (stopping early to accept only lowers it), and at or below
  /// alpha exactly when the design rejects: for k <= c_j it is at most spent(j), at the last look
  /// above alpha for any k > c_J, and above alpha whenever (k + 1)/(B_j + 1) is. For k beyond
  /// the states tracked (about alpha (B_J + 1)) an upper bound, spent(j - 1) + (k + 1)/(B_j + 1).
  double p_value(std::size_t j, std::int64_t k) const;
  /// The largest k whose p_value at look j is at most alpha (-1: none).
  std::int64_t critical(std::size_t j) const;

  enum class Decision { reject, accept, go_on };
  /// The decision at look j with k_j = k: reject on the boundary; accept when the
  /// Clopper-Pearson interval of k/B_j at level 1 - risk lies wholly above `level` (the data are
  /// clearly inside the replicates: stopping then only lowers the size) or at the last look;
  /// else go on.
  Decision decide(std::size_t j, std::int64_t k, double risk, double level) const;

 private:
  std::vector<std::int64_t> looks_;
  double alpha_ = 0.0;
  std::int64_t states_ = 0;  // k = 0 .. states_ - 1 tracked
  std::vector<std::int64_t> boundary_;
  std::vector<double> spent_;
  /// reached_[j][k]: the null probability of no rejection before look j and k_j = k.
  std::vector<std::vector<double>> reached_;
};

}  // namespace odomcov
