// Eq. 1, 5, 6 and Table I against values worked out by hand.
#include <cmath>

#include <gtest/gtest.h>

#include "pipeline/acuity.h"

namespace fovea::pipeline {
namespace {

TEST(Acuity, MarIsLinearInEccentricity) {
  // Eq. 1 in degrees: MAR(8) = 0.022 * 8 + 1/60 = 0.176 + 0.0166667.
  EXPECT_NEAR(marDeg(0.022, 8.0), 0.1926666667, 1e-10);
  EXPECT_NEAR(marDeg(0.034, 60.0), 2.0566666667, 1e-10);
  EXPECT_DOUBLE_EQ(marDeg(0.022, 0.0), 1.0 / 60.0);
}

TEST(Acuity, FoveaVoxelIsOneArcminuteAtD0) {
  // Eq. 5: v0 = 2 m * tan(1/60 deg) = 2 * 2.9088821e-4.
  EXPECT_NEAR(foveaVoxelSizeM(2.0), 5.817764337e-4, 1e-12);
}

TEST(Acuity, F3VoxelSizesAtTwoMetres) {
  // v_n = v0 * MAR(E_n) / MAR0 with E = 8, 18, 30, 60 and the far periphery at 90:
  // ratios 11.56, 24.76, 40.6, 80.2, 119.8.
  AcuityConfig config;
  config.preset = Preset::kF3;
  Result<RegionModel> model = RegionModel::create(config);
  ASSERT_TRUE(model.isOk()) << model.status().toString();
  ASSERT_EQ(model->regionCount(), 6);
  const double expected_m[] = {5.817764337e-4, 6.725335574e-3, 1.440478450e-2,
                               2.362012321e-2, 4.665846999e-2, 6.969681676e-2};
  for (int n = 0; n < 6; ++n) EXPECT_NEAR(model->voxelSizeM(n, 2.0), expected_m[n], 1e-11) << "region " << n;
  EXPECT_NEAR(model->voxelScale(1), 11.56, 1e-12);
  EXPECT_NEAR(model->voxelScale(5), 119.8, 1e-12);
}

TEST(Acuity, VoxelSizesFollowTheChainRuleOfEq6) {
  AcuityConfig config;
  config.preset = Preset::kF3;
  config.slope = 0.034;
  RegionModel model = RegionModel::create(config).value();
  for (int n = 2; n < model.regionCount(); ++n) {
    const double chained = model.voxelSizeM(n - 1, 1.5) * marDeg(0.034, model.voxelEccDeg(n)) /
                           marDeg(0.034, model.voxelEccDeg(n - 1));
    EXPECT_NEAR(model.voxelSizeM(n, 1.5), chained, 1e-15);
  }
}

TEST(Acuity, PresetsMatchSectionIII) {
  AcuityConfig config;
  config.preset = Preset::kF1;
  RegionModel f1 = RegionModel::create(config).value();
  ASSERT_EQ(f1.regionCount(), 4);
  EXPECT_EQ(f1.boundDeg(0), 5.0);
  EXPECT_EQ(f1.boundDeg(1), 8.0);
  EXPECT_EQ(f1.boundDeg(2), 18.0);
  EXPECT_EQ(f1.voxelEccDeg(3), 90.0);  // the rest: far-peripheral voxel size
  EXPECT_STREQ(f1.regionName(0), "fovea");

  config.preset = Preset::kF2;
  RegionModel f2 = RegionModel::create(config).value();
  ASSERT_EQ(f2.regionCount(), 5);
  EXPECT_EQ(f2.boundDeg(3), 30.0);
  EXPECT_EQ(f2.voxelEccDeg(3), 30.0);
  EXPECT_EQ(f2.voxelEccDeg(4), 90.0);

  config.preset = Preset::kF3;
  config.far_ecc_deg = 100.0;
  RegionModel f3 = RegionModel::create(config).value();
  ASSERT_EQ(f3.regionCount(), 6);
  EXPECT_EQ(f3.boundDeg(4), 60.0);
  EXPECT_EQ(f3.voxelEccDeg(5), 100.0);

  config.preset = Preset::kFRef;
  RegionModel fref = RegionModel::create(config).value();
  EXPECT_EQ(fref.regionCount(), 1);
}

TEST(Acuity, ParsesPresetNames) {
  EXPECT_EQ(parsePreset("f2").value(), Preset::kF2);
  EXPECT_EQ(parsePreset("FREF").value(), Preset::kFRef);
  Result<Preset> bad = parsePreset("F9");
  ASSERT_FALSE(bad.isOk());
  EXPECT_NE(bad.status().message().find("F9"), std::string::npos);
}

struct BadConfig {
  std::vector<double> bounds;
  double slope;
  double far;
  const char* field;
};

void PrintTo(const BadConfig& c, std::ostream* os) { *os << c.field; }

class AcuityRejects : public ::testing::TestWithParam<BadConfig> {};

TEST_P(AcuityRejects, NamesTheField) {
  AcuityConfig config;
  config.preset = Preset::kCustom;
  config.custom_bounds_deg = GetParam().bounds;
  config.slope = GetParam().slope;
  config.far_ecc_deg = GetParam().far;
  Result<RegionModel> model = RegionModel::create(config);
  ASSERT_FALSE(model.isOk());
  EXPECT_EQ(model.status().code(), ErrorCode::kInvalidArgument);
  EXPECT_NE(model.status().message().find(GetParam().field), std::string::npos) << model.status().message();
}

INSTANTIATE_TEST_SUITE_P(
    Custom, AcuityRejects,
    ::testing::Values(BadConfig{{5, 18, 8}, 0.022, 90, "bounds_deg[2]"},      // unsorted
                      BadConfig{{5, 8, 8}, 0.022, 90, "bounds_deg[2]"},       // duplicate
                      BadConfig{{0, 8}, 0.022, 90, "bounds_deg[0]"},          // at 0
                      BadConfig{{5, 180}, 0.022, 90, "bounds_deg[1]"},        // at 180
                      BadConfig{{-3}, 0.022, 90, "bounds_deg[0]"},            // negative
                      BadConfig{{5, NAN}, 0.022, 90, "bounds_deg[1]"},        // NaN
                      BadConfig{{5, 8}, -0.01, 90, "slope"},                  // negative m
                      BadConfig{{5, 8}, NAN, 90, "slope"},                    // NaN m
                      BadConfig{{5, 8}, 0.022, NAN, "far_ecc_deg"},           // NaN far
                      BadConfig{{5, 8, 100}, 0.022, 90, "far_ecc_deg"},       // far below last bound
                      BadConfig{{1, 2, 3, 4, 5, 6, 7, 8}, 0.022, 90, "bounds_deg"}));  // too many

TEST(Acuity, AcceptsCustomListsIncludingBeyond90) {
  AcuityConfig config;
  config.preset = Preset::kCustom;
  config.custom_bounds_deg = {2.5, 10, 90, 120};
  config.far_ecc_deg = 150;
  Result<RegionModel> model = RegionModel::create(config);
  ASSERT_TRUE(model.isOk()) << model.status().toString();
  EXPECT_EQ(model->regionCount(), 5);
  EXPECT_EQ(model->voxelEccDeg(2), 90.0);
  EXPECT_EQ(model->voxelEccDeg(4), 150.0);
}

}  // namespace
}  // namespace fovea::pipeline
