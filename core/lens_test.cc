#include "core/lens.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/error.h"
#include "core/files.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

VignettingModel Model() {
  VignettingModel m;
  m.width = 120;
  m.height = 80;
  m.cx = 64;
  m.cy = 38;
  m.a = {-0.3, 0.05, -0.01};
  return m;
}

std::string ErrorOf(const std::string& path) {
  try {
    ReadLensFile(path);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(LensTest, FalloffIsTheEvenPolynomialOfTheNormalisedRadius) {
  const VignettingModel m = Model();
  EXPECT_DOUBLE_EQ(m.Falloff(m.cx, m.cy), 1.0);
  const double hd = 0.5 * std::hypot(120.0, 80.0);
  const double r = std::hypot(100 - m.cx, 10 - m.cy) / hd;
  EXPECT_NEAR(m.Falloff(100, 10), 1 - 0.3 * r * r + 0.05 * std::pow(r, 4) - 0.01 * std::pow(r, 6),
              1e-15);
  // The farthest corner from (64, 38) is (0, 80).
  EXPECT_NEAR(m.MaxRadius(), std::hypot(64.0, 42.0) / hd, 1e-15);
}

TEST(LensTest, RemovingTheModelFlattensAFieldAtAnySizeOfTheSameAspect) {
  const VignettingModel m = Model();
  Image im(m.width, m.height, 3, PixelUnits::kRadiance);
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x)
      for (int c = 0; c < 3; ++c) im.at(x, y, c) = 5.f * m.Falloff(x + 0.5, y + 0.5);
  RemoveVignetting(m, &im);
  for (float v : im.data) ASSERT_NEAR(v, 5.f, 5e-6f);
  Image half(60, 40, 1, PixelUnits::kRadiance, 1.f);
  RemoveVignetting(m, &half);
  EXPECT_NEAR(half.at(0, 0, 0), 1 / m.Falloff(1, 1), 1e-6);
  Image square(100, 100, 3, PixelUnits::kRadiance, 1.f);
  EXPECT_THROW(RemoveVignetting(m, &square), Error);
  Image digital(120, 80, 3, PixelUnits::kDigital, 1.f);
  EXPECT_THROW(RemoveVignetting(m, &digital), Error);
}

TEST(LensTest, VignettingJsonRoundTripAndValidation) {
  const VignettingModel m = Model();
  const VignettingModel back = nlohmann::json(m).get<VignettingModel>();
  EXPECT_EQ(back.width, m.width);
  EXPECT_DOUBLE_EQ(back.cy, m.cy);
  EXPECT_DOUBLE_EQ(back.a[2], m.a[2]);
  nlohmann::json j = m;
  j["a"] = {-1.5, 0, 0};  // V < 0 at the corners
  EXPECT_THROW(j.get<VignettingModel>(), Error);
  j = m;
  j.erase("cx");
  EXPECT_THROW(j.get<VignettingModel>(), Error);
  j = m;
  j["cx"] = 1e6;
  EXPECT_THROW(j.get<VignettingModel>(), Error);
  j = m;
  j["model"] = "cos4";
  EXPECT_THROW(j.get<VignettingModel>(), Error);
}

TEST(LensTest, ReadsIntrinsicsFieldAndVignetting) {
  const fs::path dir = fs::temp_directory_path() / ("rouen_lens_test_" + std::to_string(getpid()));
  fs::create_directories(dir);
  nlohmann::json j = Intrinsics::FisheyeFov(120, 80, 180);
  j["max_field_deg"] = 95;
  j["vignetting"] = Model();
  j["calibration"] = {{"rms_px", 0.2}};  // ignored
  WriteFileAtomic(dir / "fisheye.json", j.dump());
  const LensFile lens = ReadLensFile((dir / "fisheye.json").string());
  EXPECT_EQ(lens.intrinsics.projection, Projection::kFisheye);
  EXPECT_EQ(lens.intrinsics.width, 120);
  EXPECT_DOUBLE_EQ(lens.max_field_deg, 95);
  ASSERT_TRUE(lens.vignetting.has_value());
  EXPECT_DOUBLE_EQ(lens.vignetting->a[0], -0.3);
  // Neither key: no field limit, no model.
  const nlohmann::json plain = Intrinsics::PinholeFov(64, 48, 60);
  WriteFileAtomic(dir / "plain.json", plain.dump());
  const LensFile p = ReadLensFile((dir / "plain.json").string());
  EXPECT_EQ(p.max_field_deg, 0);
  EXPECT_FALSE(p.vignetting.has_value());
  fs::remove_all(dir);
}

TEST(LensTest, BadLensFilesNameTheFileAndTheProblem) {
  const fs::path dir = fs::temp_directory_path() / ("rouen_lens_bad_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const std::string missing = (dir / "missing.json").string();
  EXPECT_EQ(ErrorOf(missing), missing + ": no such lens file");
  auto write = [&](const std::string& name, const std::string& text) {
    WriteFileAtomic(dir / name, text);
    return (dir / name).string();
  };
  const std::string truncated = write("truncated.json", "{\"projection\": \"pinhole\", \"wid");
  EXPECT_EQ(ErrorOf(truncated).rfind(truncated + ": not a valid lens file", 0), 0u)
      << ErrorOf(truncated);
  nlohmann::json j = Intrinsics::PinholeFov(64, 48, 60);
  j["fx"] = -3;
  const std::string focal = write("focal.json", j.dump());
  EXPECT_EQ(ErrorOf(focal).rfind(focal + ": ", 0), 0u);
  j = Intrinsics::PinholeFov(64, 48, 60);
  j["max_field_deg"] = "wide";
  const std::string field = write("field.json", j.dump());
  EXPECT_NE(ErrorOf(field).find("max_field_deg"), std::string::npos) << ErrorOf(field);
  j["max_field_deg"] = 200;
  write("field.json", j.dump());
  EXPECT_NE(ErrorOf(field).find("0..180"), std::string::npos) << ErrorOf(field);
  j.erase("max_field_deg");
  nlohmann::json v = Model();
  v["a"] = {-2, 0, 0};
  j["vignetting"] = v;
  const std::string vig = write("vig.json", j.dump());
  EXPECT_EQ(ErrorOf(vig).rfind(vig + ": vignetting: the fall-off drops", 0), 0u) << ErrorOf(vig);
  // Found by tests/fuzz/lens_pose_fuzz: a vignetting width of 1e36 was converted to int
  // (undefined behaviour); 640.5 became 640, and an intrinsics width of 4294967936 became 640.
  for (const char* width : {"1e36", "640.5", "4294967936"}) {
    nlohmann::json w = Intrinsics::PinholeFov(64, 48, 60);
    w["vignetting"] = Model();
    w["vignetting"]["width"] = nlohmann::json::parse(width);
    const std::string file = write("width.json", w.dump());
    const std::string e = ErrorOf(file);
    EXPECT_EQ(e.rfind(file + ": vignetting: \"width\" (pixels) is ", 0), 0u) << e;
    EXPECT_TRUE(e.ends_with(", not an integer") || e.ends_with(", outside -2147483648..2147483647"))
        << e;
  }
  nlohmann::json wide = Intrinsics::PinholeFov(64, 48, 60);
  wide["width"] = 4294967936LL;
  const std::string wide_file = write("wide.json", wide.dump());
  EXPECT_NE(ErrorOf(wide_file).find("key \"width\" is 4294967936, outside"), std::string::npos)
      << ErrorOf(wide_file);
  const std::string array = write("array.json", "[1, 2]");
  EXPECT_EQ(ErrorOf(array), array + ": a lens file is a JSON object");
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
