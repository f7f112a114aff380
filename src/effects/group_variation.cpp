// group_variation {parameter, sd}: a systematic parameter of another effect in the list (e.g.
// wheelbase_error.Eb) is drawn once per experiment group (a session, a day, a floor) from
// N(value, sd^2) and shared by every run of that group (tyre pressure, floor, a re-mounted
// marker). One run alone cannot see it: the effect has no per-run hooks on either side.
//  * World side: group_effects() draws the group's value (synth calls it per experiment).
//  * Model side: likelihood.cpp (group_terms) expands each run's mean to second order in the
//    group's draw: the shift sd^2 f''/2, and the columns sd f' and sd^2 f''/sqrt(2) of the
//    group's shared constants z and (z^2 - 1)/sqrt(2); the runs of a group are correlated
//    through them.
#include <cstdint>

#include "effects/effect.hpp"
#include "odomcov/base/format.hpp"

namespace odomcov {

GroupTarget group_target(const EffectList& list) {
  GroupTarget t;
  for (const EffectSpec& g : list) {
    if (g.name != kGroupVariation) continue;
    const std::size_t dot = g.target.find('.');
    const std::string effect = g.target.substr(0, dot), param = g.target.substr(dot + 1);
    for (std::size_t e = 0; e < list.size(); ++e) {
      if (list[e].name != effect) continue;
      const EffectInfo* info = info_of(list[e]);
      for (std::size_t p = 0; p < info->parameters.size(); ++p) {
        if (info->parameters[p].name == param) t = {true, e, p, g.values[0]};
      }
    }
  }
  return t;
}

namespace {

/// The counter's run word of a group's draw: FNV-1a of its name.
std::uint64_t group_stream(const std::string& group) {
  std::uint64_t h = 0xcbf29ce484222325ull;  // FNV-1a 64
  for (const unsigned char c : group) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

}  // namespace

EffectList group_effects(const EffectList& list, std::uint64_t seed, const std::string& group) {
  const GroupTarget t = group_target(list);
  EffectList drawn = list;
  if (t.present && t.sd > 0.0) {
    const auto key = random::key_from_seed(random::derive_seed(seed, random::kGroupSeedStream));
    const double z = random::normal_at(key, group_stream(group), 0, random::kTagGroup);
    EffectSpec& varied = drawn[t.effect];
    varied.values[t.parameter] += t.sd * z;
    if (const std::string error = check_effect(varied); !error.empty()) {
      throw EffectError("effects." + std::string(kGroupVariation) + ".sd",
                        "the draw for group '" + group + "' gives " + error +
                            ": sd is too large for " + list[t.effect].name);
    }
  }
  EffectList out;
  for (const EffectSpec& e : drawn) {
    if (!info_of(e)->grouped) out.push_back(e);
  }
  return out;
}

namespace effects {
namespace {

class GroupVariation final : public Effect {
 public:
  explicit GroupVariation(double sd) : sd_(sd) {}
  std::string non_gaussian() const override {
    return sd_ > 0 ? "a parameter drawn once per group (a mean that is nonlinear in the draw)" : "";
  }

 private:
  double sd_;
};

}  // namespace

EffectType group_variation_type() {
  return {{kGroupVariation,
           {{"sd", "", 0.0, 1e300, false, false, 0.0, 0.005}},
           "a parameter that changes from group to group (session, day, floor: tyre pressure, "
           "load, surface)",
           "the runs' mean residuals cluster by group: runs of one group share an offset that "
           "differs between groups, beyond what the noise explains",
           "`parameter` (e.g. wheelbase_error.Eb) drawn once per group from N(value, sd^2)",
           /*systematic=*/true, /*grouped=*/true},
          [](const std::vector<double>& v) -> std::unique_ptr<Effect> {
            return std::make_unique<GroupVariation>(v[0]);
          }};
}

}  // namespace effects
}  // namespace odomcov
