#include "core/response_curve.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/files.h"

namespace rouen {
namespace {

// A gamma-like curve: exposure = (z / 255)^2.2 scaled per channel, with a flat top.
ResponseCurve MakeCurve() {
  ResponseCurve r;
  for (int c = 0; c < 3; ++c) {
    r.g[c].resize(256);
    for (int z = 0; z < 256; ++z) {
      r.g[c][z] = 2.2 * std::log((z + 1.0) / 256.0) + 0.1 * c;
    }
    for (int z = 250; z < 256; ++z) r.g[c][z] = r.g[c][249];  // saturation plateau
  }
  return r;
}

TEST(ResponseCurveTest, Validity) {
  EXPECT_TRUE(MakeCurve().valid());
  EXPECT_FALSE(ResponseCurve().valid());
  ResponseCurve r = MakeCurve();
  r.g[1][100] = r.g[1][99] - 0.01;
  EXPECT_FALSE(r.valid());
  r = MakeCurve();
  r.g[2][7] = NAN;
  EXPECT_FALSE(r.valid());
  r = MakeCurve();
  r.g[0].pop_back();
  EXPECT_FALSE(r.valid());
}

TEST(ResponseCurveTest, InterpolatesAndInverts) {
  const ResponseCurve r = MakeCurve();
  EXPECT_DOUBLE_EQ(r.LogExposure(1, 10), r.g[1][10]);
  EXPECT_DOUBLE_EQ(r.LogExposure(1, 10.25), 0.75 * r.g[1][10] + 0.25 * r.g[1][11]);
  EXPECT_DOUBLE_EQ(r.LogExposure(0, -3), r.g[0][0]);
  EXPECT_DOUBLE_EQ(r.LogExposure(0, 300), r.g[0][255]);
  EXPECT_DOUBLE_EQ(r.LogExposure(2, 255), r.g[2][255]);
  for (int c = 0; c < 3; ++c) {
    for (double z = 0.0; z <= 249.0; z += 0.37) {
      EXPECT_NEAR(r.DigitalValue(c, std::exp(r.LogExposure(c, z))), z, 1e-9) << c << " " << z;
    }
  }
  // Clamped at both ends; zero or negative exposure gives 0.
  EXPECT_EQ(r.DigitalValue(0, std::exp(r.g[0][0]) * 0.5), 0.0);
  EXPECT_EQ(r.DigitalValue(0, 0.0), 0.0);
  EXPECT_EQ(r.DigitalValue(0, -1.0), 0.0);
  EXPECT_EQ(r.DigitalValue(0, 1e6), 255.0);
  EXPECT_EQ(r.DigitalValue(0, std::exp(r.g[0][255])), 255.0);  // on the plateau
}

TEST(ResponseCurveTest, JsonAndFiles) {
  const ResponseCurve r = MakeCurve();
  const nlohmann::json j = r;
  ASSERT_TRUE(j.contains("g"));
  EXPECT_EQ(j["g"].size(), 3u);
  EXPECT_EQ(j["g"][0].size(), 256u);
  EXPECT_EQ(j.get<ResponseCurve>().g, r.g);

  const auto dir =
      std::filesystem::temp_directory_path() / ("rouen_core_curve_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string path = (dir / "response.json").string();
  WriteResponseCurve(path, r);
  EXPECT_EQ(ReadResponseCurve(path).g, r.g);

  ResponseCurve bad = MakeCurve();
  bad.g[0][3] = 100;
  EXPECT_THROW(WriteResponseCurve(path, bad), Error);

  auto expect_error = [&](const std::string& text, const std::string& phrase) {
    WriteFileAtomic(path, text);
    try {
      ReadResponseCurve(path);
      ADD_FAILURE() << text.substr(0, 60);
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(phrase), std::string::npos) << e.what();
    }
  };
  expect_error("{", "JSON");
  expect_error("{\"h\": []}", "\"g\"");
  expect_error("{\"g\": [[1,2],[3],[4]]}", "256");
  nlohmann::json dec = r;
  dec["g"][1][40] = -100.0;
  expect_error(dec.dump(), "decreases");
  nlohmann::json str = r;
  str["g"][2][5] = "x";
  expect_error(str.dump(), "not a number");
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace rouen
