// Every one of the 2^32 words through the normal generator (src/base/normal_icdf-inl.hpp,
// docs/performance.md, "Normals"): the largest relative error against the exact quantile at the
// word's grid point, sqrt(2) erfc^-1((m + 1/2) 2^-31) in double by Boost.Math (itself good to
// ~1e-16), by octave of the magnitude m; and, for every SIMD target this CPU runs, whether its
// normals are the scalar generator's bits for every word. Both halves run on all cores (TBB).
// Run: normal_icdf_accuracy [step = 1]   (step > 1 checks every step-th magnitude)
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <boost/math/special_functions/erf.hpp>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

#include "base/random.hpp"
#include "engine/lane_plan.hpp"

namespace {

using odomcov::random::normal_from_word;

struct Worst {
  std::array<double, 32> rel{};  // by octave of m (index 0: m = 0)
  std::uint64_t differ = 0;      // words whose target bits differ from the scalar's
};

int octave(std::uint32_t m) {
  return m == 0 ? 0 : 32 - __builtin_clz(m);
}

}  // namespace

int main(int argc, char** argv) {
  const std::uint64_t step = argc > 1 ? std::strtoull(argv[1], nullptr, 10) : 1;
  const std::uint64_t magnitudes = (std::uint64_t{1} << 31) / step;
  constexpr std::uint64_t kChunk = 1 << 16;
  // Accuracy over the magnitudes (the sign is a bit flip: Random.NormalsAreOddInTheSignBit).
  const Worst acc = tbb::parallel_reduce(
      tbb::blocked_range<std::uint64_t>(0, magnitudes, kChunk), Worst{},
      [&](const tbb::blocked_range<std::uint64_t>& r, Worst w) {
        for (std::uint64_t i = r.begin(); i != r.end(); ++i) {
          const auto m = static_cast<std::uint32_t>(i * step);
          const double exact = std::sqrt(2.0) * boost::math::erfc_inv((m + 0.5) * 0x1p-31);
          const double rel = std::abs(static_cast<double>(normal_from_word(m)) - exact) / exact;
          double& slot = w.rel[static_cast<std::size_t>(octave(m))];
          slot = std::max(slot, rel);
        }
        return w;
      },
      [](Worst a, const Worst& b) {
        for (std::size_t o = 0; o < a.rel.size(); ++o) a.rel[o] = std::max(a.rel[o], b.rel[o]);
        return a;
      });
  double worst = 0.0;
  std::printf(
      "largest relative error against the exact quantile, by octave of m (%llu magnitudes):\n",
      static_cast<unsigned long long>(magnitudes));
  for (int o = 0; o < 32; ++o) {
    const double lo = o == 0 ? 0.0 : std::ldexp(1.0, o - 1);
    const double z = std::sqrt(2.0) * boost::math::erfc_inv((lo + 0.5) * 0x1p-31);
    std::printf("  m in [%.0f, %.0f)  |z| <= %.3f  %.3g\n", lo, std::ldexp(1.0, o), z,
                acc.rel[static_cast<std::size_t>(o)]);
    worst = std::max(worst, acc.rel[static_cast<std::size_t>(o)]);
  }
  std::printf("largest: %.3g\n", worst);
  // Every word (both signs) through every target against the scalar bits.
  const std::uint64_t words = (std::uint64_t{1} << 32) / step;
  for (const odomcov::lanes::Target& t : odomcov::lanes::supported_targets()) {
    const std::uint64_t differ = tbb::parallel_reduce(
        tbb::blocked_range<std::uint64_t>(0, words, kChunk), std::uint64_t{0},
        [&](const tbb::blocked_range<std::uint64_t>& r, std::uint64_t d) {
          std::vector<std::uint32_t> in(r.size());
          std::vector<float> out(r.size());
          for (std::uint64_t i = r.begin(); i != r.end(); ++i)
            in[i - r.begin()] = static_cast<std::uint32_t>(i * step);
          t.normals(in.data(), in.size(), out.data());
          for (std::size_t j = 0; j < in.size(); ++j) {
            const float s = normal_from_word(in[j]);
            d += std::memcmp(&s, &out[j], sizeof s) != 0;
          }
          return d;
        },
        [](std::uint64_t a, std::uint64_t b) { return a + b; });
    std::printf("%-8s %llu of %llu words differ from the scalar generator\n", t.name,
                static_cast<unsigned long long>(differ), static_cast<unsigned long long>(words));
  }
  return 0;
}
