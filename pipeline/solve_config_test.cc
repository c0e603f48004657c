#include "pipeline/solve_config.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include "core/error.h"
#include "core/files.h"

namespace rouen {
namespace {

using nlohmann::json;

std::string ErrorOf(const json& j) {
  try {
    ApplySolveConfig(j, DefaultSolveConfig(false), "solve.toml");
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(SolveConfigTest, EveryFieldRoundTripsThroughItsJson) {
  SolveConfig c = DefaultSolveConfig(true);
  c.grid.block_spacing_m["ground"] = 2.5;
  c.sky_fit.weighting = SkyWeighting::kPaper;
  c.sky_fit.norm_p = 2;
  c.environment.sectors = 36;
  c.albedo.loss = RobustLoss::kPaper;
  c.albedo.irradiance.method = IrradianceMethod::kMonteCarlo;  // not the default
  c.albedo.observation.check_footprint = false;
  c.ground.radius_m = 12;
  c.ground.block = "yard";
  c.grid.block_spacing_m["yard"] = 1.5;  // as resolving the options sets it
  c.sun.clip_radiance = 0;               // a float32 sun frame: no value is clipped
  c.sun.search_radius_deg = 5;
  c.sky_samples.max_samples = 5000;
  c.sky_samples.seed = 7;
  c.sky_segment.min_relative_blue_ratio = 0.4;
  c.albedo.irls_tolerance = 1e-3;
  c.albedo.relative_error_floor = 0.1;
  c.albedo.outer_newton = false;  // the paper's plain update
  c.albedo.outer_quantile = 0.9;
  c.albedo.sun_lobe.model = LobeModel::kMicrofacet;  // not the default
  c.albedo.sky_lobe.source = SkyLobeOptions::Source::kFit;
  c.albedo.sky_lobe.mirror_samples = 16;
  c.env_stereo.alpha = 500;
  c.env_stereo.sky_irradiance = EnvSkyIrradiance::kAmbient;
  c.response.method = ResponseMethod::kRobertson;
  c.response.samples_per_bracket = 400;
  c.merge.ghost_removal = true;
  c.merge.saturation_level = 240;
  c.radiance_merge.clip_ramp = 0.05;
  c.ground_field.use = GroundFieldUse::kAlways;  // not the default
  c.ground_field.walls = false;
  c.ground_field.open_sky = 0.75;
  c.surroundings_from_panoramas = false;  // not the default
  c.environment.fill_band_residual = false;
  const json j = SolveConfigJson(c);
  const SolveConfig back = ApplySolveConfig(j, DefaultSolveConfig(false), "x");
  EXPECT_EQ(SolveConfigJson(back), j);
  EXPECT_EQ(back.response_max_brackets, 6);
  EXPECT_EQ(back.environment.pixel_stride, 2);
  EXPECT_EQ(back.albedo.irradiance.method, IrradianceMethod::kMonteCarlo);
  EXPECT_EQ(back.sun.clip_radiance, 0);
  EXPECT_EQ(back.sky_samples.seed, 7u);
  EXPECT_EQ(back.sky_segment.min_relative_blue_ratio, 0.4);
  EXPECT_EQ(back.albedo.relative_error_floor, 0.1);
  EXPECT_EQ(back.albedo.sun_lobe.model, LobeModel::kMicrofacet);
  EXPECT_EQ(back.albedo.sky_lobe.source, SkyLobeOptions::Source::kFit);
  EXPECT_EQ(back.albedo.sky_lobe.mirror_samples, 16);
  EXPECT_EQ(back.env_stereo.alpha, 500);
  EXPECT_EQ(back.env_stereo.sky_irradiance, EnvSkyIrradiance::kAmbient);
  EXPECT_FALSE(back.surroundings_from_panoramas);
  EXPECT_FALSE(back.environment.fill_band_residual);
  EXPECT_FALSE(DefaultSolveConfig(false).albedo.sun_lobe.model.has_value());  // "auto"
  c.albedo.sun_lobe.model = LobeModel::kLafortune;                            // eq. 13's alone
  EXPECT_EQ(
      ApplySolveConfig(SolveConfigJson(c), DefaultSolveConfig(false), "x").albedo.sun_lobe.model,
      LobeModel::kLafortune);
  EXPECT_EQ(back.response.method, ResponseMethod::kRobertson);
  EXPECT_EQ(back.response.samples_per_bracket, 400);
  EXPECT_TRUE(back.merge.ghost_removal);
  EXPECT_EQ(back.merge.saturation_level, 240);
  EXPECT_EQ(back.radiance_merge.clip_ramp, 0.05);
  EXPECT_EQ(back.ground_field.use, GroundFieldUse::kAlways);
  EXPECT_FALSE(back.ground_field.walls);
  EXPECT_EQ(back.ground_field.open_sky, 0.75);
  // The field's three uses, as the config writes them: true, false and "with_surroundings".
  for (const GroundFieldUse use :
       {GroundFieldUse::kNever, GroundFieldUse::kWithSurroundings, GroundFieldUse::kAlways}) {
    c.ground_field.use = use;
    EXPECT_EQ(ApplySolveConfig(SolveConfigJson(c), DefaultSolveConfig(false), "x").ground_field.use,
              use);
  }
}

TEST(SolveConfigTest, DefaultsAndQuick) {
  const SolveConfig full = DefaultSolveConfig(false), quick = DefaultSolveConfig(true);
  EXPECT_EQ(full.response_max_brackets, 12);
  EXPECT_EQ(quick.response_max_brackets, 6);
  EXPECT_EQ(full.environment.pixel_stride, 1);
  EXPECT_EQ(quick.environment.pixel_stride, 2);
  EXPECT_EQ(full.sky_fit.weighting, SkyWeighting::kRelative);
  EXPECT_EQ(full.sky_fit.norm_p, 1);
  // No block of any particular model is special by default.
  EXPECT_TRUE(full.grid.block_spacing_m.empty());
  EXPECT_EQ(full.grid.SpacingFor("plaza"), 0.6);
  EXPECT_EQ(full.ground.radius_m, 0);  // the ground is not modelled unless asked
  // The ground as a light field when the session gives the surroundings.
  EXPECT_EQ(full.ground_field.use, GroundFieldUse::kWithSurroundings);
}

// The modelled ground gets its own grid spacing unless the grid names its block.
TEST(SolveConfigTest, TheModelledGroundsGrid) {
  SolveConfig c = ApplySolveConfig(json::parse(R"({"ground": {"radius_m": 30}})"),
                                   DefaultSolveConfig(false), "solve.toml");
  EXPECT_EQ(c.ground.radius_m, 30);
  EXPECT_EQ(c.grid.SpacingFor("ground"), 1.5);
  c = ApplySolveConfig(json::parse(R"({"ground": {"radius_m": 30, "block": "yard", "spacing_m": 3},
                      "grid": {"block_spacing_m": {"yard": 2}}})"),
                       DefaultSolveConfig(false), "solve.toml");
  EXPECT_EQ(c.grid.SpacingFor("yard"), 2);
  EXPECT_EQ(c.grid.SpacingFor("ground"), 0.6);
  EXPECT_NE(ErrorOf(json::parse(R"({"ground": {"radius_m": -3}})"))
                .find("ground.radius_m must be a number within 0..10000"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"ground": {"block": ""}})"))
                .find("ground.block must be a non-empty string"),
            std::string::npos);
}

// A session's own options (its rig's [solve] table) come between the defaults and a user's
// file; each layer sets the keys it names and keeps the others.
TEST(SolveConfigTest, SessionOptionsAreTheStart) {
  SessionInfo info;
  info.solve_config = json::parse(R"({"grid": {"block_spacing_m": {"plaza": 1.5}}})");
  const SolveConfig c = SessionSolveConfig(info, "s/session.json", true);
  EXPECT_EQ(c.grid.SpacingFor("plaza"), 1.5);
  EXPECT_EQ(c.response_max_brackets, 6);  // quick
  const SolveConfig user = ApplySolveConfig(
      json::parse(R"({"grid": {"block_spacing_m": {"ground": 2}}})"), c, "solve.toml");
  EXPECT_EQ(user.grid.SpacingFor("plaza"), 1.5);
  EXPECT_EQ(user.grid.SpacingFor("ground"), 2);
  info.solve_config = json::parse(R"({"grid": {"spacing": 1}})");
  try {
    SessionSolveConfig(info, "s/session.json", false);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("s/session.json: extra.solve_config"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("grid.spacing"), std::string::npos) << e.what();
  }
}

TEST(SolveConfigTest, AFileChangesOnlyWhatItNames) {
  const SolveConfig c =
      ApplySolveConfig(json::parse(R"({"sky_fit": {"norm_p": 2}})"), DefaultSolveConfig(true), "x");
  EXPECT_EQ(c.sky_fit.norm_p, 2);
  json expected = SolveConfigJson(DefaultSolveConfig(true));
  expected["sky_fit"]["norm_p"] = 2.0;
  EXPECT_EQ(SolveConfigJson(c), expected);
}

TEST(SolveConfigTest, StrictKeysTypesAndRanges) {
  EXPECT_NE(ErrorOf(json::parse(R"({"skyfit": {}})")).find("solve.toml: skyfit is not a known key"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"sky_fit": {"norm": 2}})"))
                .find("solve.toml: sky_fit.norm is not a known key (sky_fit takes: "),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"sky_fit": {"norm_p": 0.5}})"))
                .find("sky_fit.norm_p must be a number within 1..16"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"sky_fit": {"weighting": "absolute"}})"))
                .find("sky_fit.weighting must be one of paper, relative"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"hemisphere": {"directions": 2.5}})"))
                .find("hemisphere.directions must be an integer"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"albedo": {"irradiance": {"ground_shadow": 1}}})"))
                .find("albedo.irradiance.ground_shadow must be true or false"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"grid": {"block_spacing_m": {"plaza": -1}}})"))
                .find("grid.block_spacing_m.plaza must be a number"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"grid": 3})")).find("grid must be a table"), std::string::npos);
  // The sun's, the sky samples' and the sky segmentation's options, once built on the spot.
  EXPECT_NE(ErrorOf(json::parse(R"({"sun": {"clip_radiance": -1}})"))
                .find("sun.clip_radiance must be a number within 0.."),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"sun": {"annulus_outer_factor": 2}})"))
                .find("annulus_inner_factor < annulus_outer_factor"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"sky_samples": {"max_samples": 0}})"))
                .find("sky_samples.max_samples must be an integer"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"albedo": {"relative_error_floor": 2}})"))
                .find("albedo.relative_error_floor must be a number within 0..1"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"env_stereo": {"sky_irradiance": "sphere"}})"))
                .find("env_stereo.sky_irradiance must be one of ambient, plane"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"env_stereo": {"ground_retro": 0.5}})"))
                .find("env_stereo.ground_retro is not a known key"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"albedo": {"sun_lobe": {"model": "ggx"}}})"))
                .find("albedo.sun_lobe.model must be one of auto, lafortune, microfacet"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"albedo": {"sky_lobe": {"source": "paper"}}})"))
                .find("albedo.sky_lobe.source must be one of sun, fit"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"response": {"method": "debevec-malik"}})"))
                .find("response.method must be one of debevec, robertson, mitsunaga"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"merge": {"dark_level": 200, "saturation_level": 100}})"))
                .find("MergeOptions: need 0 <= dark_level < saturation_level"),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"ground_field": {"enabled": "yes"}})"))
                .find("ground_field.enabled must be true, false or \"with_surroundings\""),
            std::string::npos);
  EXPECT_NE(ErrorOf(json::parse(R"({"sky_segment": {"seed_cone": 5}})"))
                .find("sky_segment.seed_cone is not a known key"),
            std::string::npos);
}

TEST(SolveConfigTest, TomlFile) {
  namespace fs = std::filesystem;
  const fs::path d = fs::temp_directory_path() / ("rouen_solve_config_" + std::to_string(getpid()));
  fs::create_directories(d);
  WriteFileAtomic(d / "solve.toml",
                  "# a user's overrides\n[sky_fit]\nnorm_p = 2\nweighting = \"paper\"\n"
                  "[grid.block_spacing_m]\nground = 2\n[albedo.irradiance]\nmethod = "
                  "\"monte_carlo\"\n");
  const SolveConfig c = ReadSolveConfigFile((d / "solve.toml").string(), DefaultSolveConfig(false));
  EXPECT_EQ(c.sky_fit.norm_p, 2);
  EXPECT_EQ(c.sky_fit.weighting, SkyWeighting::kPaper);
  EXPECT_EQ(c.grid.SpacingFor("ground"), 2);
  EXPECT_EQ(c.grid.SpacingFor("plaza"), 0.6);
  EXPECT_EQ(c.albedo.irradiance.method, IrradianceMethod::kMonteCarlo);
  EXPECT_EQ(DefaultSolveConfig(false).albedo.irradiance.method, IrradianceMethod::kVectorFlux);
  WriteFileAtomic(d / "bad.toml", "[sky_fit]\nnorm_p = = 2\n");
  try {
    ReadSolveConfigFile((d / "bad.toml").string(), DefaultSolveConfig(false));
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bad.toml:2"), std::string::npos) << e.what();
  }
  WriteFileAtomic(d / "typo.toml", "[enviroment]\npixel_stride = 2\n");
  try {
    ReadSolveConfigFile((d / "typo.toml").string(), DefaultSolveConfig(false));
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("typo.toml: enviroment is not a known key"),
              std::string::npos)
        << e.what();
  }
  WriteFileAtomic(d / "nan.toml", "[sky_fit]\nnorm_p = nan\n");
  EXPECT_THROW(ReadSolveConfigFile((d / "nan.toml").string(), DefaultSolveConfig(false)), Error);
  fs::remove_all(d);
}

}  // namespace
}  // namespace rouen
