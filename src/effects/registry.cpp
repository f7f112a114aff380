// The one place effects are registered, in the SPEC catalogue's order. To add an effect, write
// src/effects/<name>.cpp (world side and model side together, see effect.hpp) and add its
// line here.
#include "effects/effect.hpp"

namespace odomcov::effects {

EffectType wheel_diameter_ratio_type();
EffectType wheelbase_error_type();
EffectType scale_error_type();
EffectType wheel_noise_correlation_type();
EffectType turn_slip_type();
EffectType per_run_radius_type();
EffectType bumps_type();
EffectType turn_dependent_wheelbase_type();
EffectType backlash_type();
EffectType reference_offset_type();
EffectType group_variation_type();
EffectType arc_skid_type();
EffectType acceleration_slip_type();

const std::vector<EffectType>& registry() {
  static const std::vector<EffectType> types{
      wheel_diameter_ratio_type(), wheelbase_error_type(), scale_error_type(),
      wheel_noise_correlation_type(), turn_slip_type(), per_run_radius_type(), bumps_type(),
      turn_dependent_wheelbase_type(), backlash_type(), reference_offset_type(),
      group_variation_type(), arc_skid_type(), acceleration_slip_type(),
  };
  return types;
}

}  // namespace odomcov::effects
