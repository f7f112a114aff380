// The simulator's SIMD kernel (lane_kernel-inl.hpp) compiled for every instruction set Highway
// targets on this architecture, and the list of those this CPU supports. x86-64: AVX-512 (AVX3),
// AVX2, SSE4 and Highway's portable 128-bit emulation; aarch64: NEON and the emulation. SVE is
// left out (its vectors have no fixed size to lay a block of runs out on) and so is SSSE3
// (SSE4's speed; x86-64 CPUs without SSE4 run the emulation).
#define HWY_DISABLED_TARGETS (HWY_SSSE3 | HWY_SVE | HWY_SVE2 | HWY_SVE_256 | HWY_SVE2_128)

#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "engine/lane_kernels.cpp"
#include <hwy/foreach_target.h>  // IWYU pragma: keep
#include <hwy/highway.h>

#include "engine/lane_kernel-inl.hpp"

HWY_BEFORE_NAMESPACE();
namespace odomcov::lanes::HWY_NAMESPACE {

Target describe() {
  return {hwy::TargetName(HWY_TARGET), HWY_TARGET, kN, kBlock, &run_blocks, &normals_of_words};
}

}  // namespace odomcov::lanes::HWY_NAMESPACE
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace odomcov::lanes {

std::vector<Target> supported_targets() {
  using Describe = Target (*)();
  // Best first; entries of targets not compiled here are null.
  const Describe compiled[] = {
      HWY_CHOOSE_AVX3_DL(describe), HWY_CHOOSE_AVX3(describe),     HWY_CHOOSE_AVX2(describe),
      HWY_CHOOSE_SSE4(describe),    HWY_CHOOSE_SSSE3(describe),    HWY_CHOOSE_SVE2_128(describe),
      HWY_CHOOSE_SVE_256(describe), HWY_CHOOSE_SVE2(describe),     HWY_CHOOSE_SVE(describe),
      HWY_CHOOSE_NEON(describe),    HWY_CHOOSE_FALLBACK(describe),
  };
  const std::int64_t supported = hwy::SupportedTargets();
  std::vector<Target> out;
  const Describe fallback = compiled[sizeof compiled / sizeof compiled[0] - 1];
  for (const Describe d : compiled) {
    if (d == nullptr) continue;
    const Target t = d();
    bool listed = false;
    for (const Target& o : out) listed = listed || o.bit == t.bit;
    if (!listed && (d == fallback || (supported & t.bit) != 0)) out.push_back(t);
  }
  return out;
}

}  // namespace odomcov::lanes
#endif  // HWY_ONCE
