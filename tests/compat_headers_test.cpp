// The flat include paths of earlier releases still work (docs/library.md, "Include paths"): each
// forwarding header brings in its layered header, so code written against them compiles and
// links unchanged for one release.
#include <gtest/gtest.h>

#include "odomcov/calibration.hpp"
#include "odomcov/closed_form.hpp"
#include "odomcov/comparison.hpp"
#include "odomcov/config.hpp"
#include "odomcov/csv_import.hpp"
#include "odomcov/diagnosis.hpp"
#include "odomcov/effects.hpp"
#include "odomcov/error.hpp"
#include "odomcov/format.hpp"
#include "odomcov/likelihood.hpp"
#include "odomcov/limits.hpp"
#include "odomcov/odometry_correction.hpp"
#include "odomcov/odometry_covariance.hpp"
#include "odomcov/optiodom.hpp"
#include "odomcov/path.hpp"
#include "odomcov/propagation.hpp"
#include "odomcov/residual_features.hpp"
#include "odomcov/second_order.hpp"
#include "odomcov/simulator.hpp"
#include "odomcov/statistics.hpp"
#include "odomcov/suite.hpp"
#include "odomcov/suite_writer.hpp"
#include "odomcov/sweep.hpp"
#include "odomcov/validation.hpp"
#include "odomcov/world.hpp"

namespace odomcov {
namespace {

// The old odomcov/config.hpp and odomcov/suite.hpp declared the loaders beside the data; their
// forwarding headers still do. Taking the functions' addresses checks declaration and linkage.
TEST(CompatHeaders, OldPathsDeclareWhatTheyDid) {
  EXPECT_NE(&load_config, nullptr);
  EXPECT_NE(&load_suite, nullptr);
  EXPECT_NE(&load_effects, nullptr);
  const Path path{100.0, {{0, 0, 0}, {1, 1, 1}}};
  EXPECT_DOUBLE_EQ(path_end_pose(path, 0.5).x(), 1.0);
  EXPECT_EQ(format_number(0.5), "0.5");
}

}  // namespace
}  // namespace odomcov
