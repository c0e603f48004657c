// The sky pixels SolveSession fits (§3.2): every pixel of the sky photo, automatic
// segmentation, or the session's own mask (session.json extra.sky_masks), always within the
// valid pixels.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "core/angles.h"
#include "core/error.h"
#include "core/image.h"
#include "core/session.h"
#include "pipeline/session_solve.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::TempDir;

constexpr int kSize = 96;

// The building seen from the camera.
bool Building(const Eigen::Vector3d& d) {
  const double az = std::atan2(d.x(), d.y()) / kDeg;  // from north through east
  return d.z() > 0 && az >= 0 && az <= 60 && std::asin(std::min(1.0, d.z())) < 40 * kDeg;
}

// A sky photo from a fisheye looking up: a smooth blue sky, and a grey building filling
// azimuths 0..60 deg below 40 deg elevation. Pixels outside the fisheye circle are black.
HdrGroup SkyPhoto() {
  HdrGroup g;
  g.name = "slot0/sky/view0";
  g.target = Target::kSky;
  g.intrinsics = Intrinsics::FisheyeFov(kSize, kSize, 180);
  g.pose = Pose::Level(Eigen::Vector3d::Zero(), 0, 90);
  g.radiance = Image(kSize, kSize, 3, PixelUnits::kRadiance);
  g.valid.assign(kSize * kSize, 1);
  for (int y = 0; y < kSize; ++y) {
    for (int x = 0; x < kSize; ++x) {
      const Eigen::Vector3d d =
          g.pose.rotation * Unproject(g.intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5));
      Eigen::Vector3d l(0.3, 0.5, 1.0);
      l *= 1 + 0.5 * d.z();
      if (Building(d)) l = Eigen::Vector3d(0.06, 0.06, 0.06);
      for (int c = 0; c < 3; ++c) g.radiance.at(x, y, c) = static_cast<float>(l[c]);
    }
  }
  return g;
}

Eigen::Vector3d DirectionOf(const HdrGroup& g, int x, int y) {
  return g.pose.rotation * Unproject(g.intrinsics, Eigen::Vector2d(x + 0.5, y + 0.5));
}

Session MakeSession(const fs::path& dir, const nlohmann::json& sky_masks) {
  SessionInfo info;
  if (!sky_masks.is_null()) info.extra["sky_masks"] = sky_masks;  // as a user might write it
  SessionWriter::Create(dir, info);
  return Session::Load(dir);
}

// The error loading a session whose session.json holds `sky_masks`.
std::string LoadErrorOf(const fs::path& dir, const nlohmann::json& sky_masks) {
  try {
    MakeSession(dir, sky_masks);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

std::string ErrorOf(const Session& s, const HdrGroup& g) {
  try {
    SkyMaskFor(s, g, Eigen::Vector3d(0, -1, 1).normalized(), SkySegmentOptions{});
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(SkyMaskTest, WithoutAnEntryEveryValidPixelCounts) {
  const fs::path dir = TempDir("skymask_all");
  const Session s = MakeSession(dir / "session", nullptr);
  HdrGroup g = SkyPhoto();
  g.valid[3 * kSize + 4] = 0;
  std::string source;
  const std::vector<uint8_t> m =
      SkyMaskFor(s, g, Eigen::Vector3d(0, -1, 1).normalized(), SkySegmentOptions{}, &source);
  EXPECT_EQ(source, "all");
  EXPECT_EQ(m, g.valid);
  fs::remove_all(dir);
}

TEST(SkyMaskTest, AutomaticSegmentationKeepsTheSkyAndDropsTheBuilding) {
  const fs::path dir = TempDir("skymask_auto");
  const Session s = MakeSession(dir / "session", {{"*", "auto"}});
  HdrGroup g = SkyPhoto();
  // A block of pixels no frame exposed well: never fitted, sky or not.
  for (int y = 10; y < 20; ++y)
    for (int x = 40; x < 56; ++x) g.valid[y * kSize + x] = 0;
  const Eigen::Vector3d sun = Eigen::Vector3d(0, -1, 1).normalized();  // south, 45 deg
  std::string source;
  const std::vector<uint8_t> m = SkyMaskFor(s, g, sun, SkySegmentOptions{}, &source);
  EXPECT_EQ(source, "automatic");
  int building = 0, building_kept = 0, open_sky = 0, open_sky_kept = 0;
  for (int y = 0; y < kSize; ++y) {
    for (int x = 0; x < kSize; ++x) {
      const size_t p = static_cast<size_t>(y) * kSize + x;
      const Eigen::Vector3d d = DirectionOf(g, x, y);
      if (!g.valid[p]) {
        EXPECT_EQ(m[p], 0) << x << "," << y;
        continue;
      }
      if (Building(d)) {
        ++building;
        building_kept += m[p];
      } else if (d.z() > std::sin(10 * kDeg) && d.dot(sun) < std::cos(10 * kDeg)) {
        // Clear of the building's edge by a pixel (~2 deg) and of the sun's exclusion.
        bool near_edge = false;
        for (int dy = -2; dy <= 2; ++dy)
          for (int dx = -2; dx <= 2; ++dx) near_edge |= Building(DirectionOf(g, x + dx, y + dy));
        if (near_edge) continue;
        ++open_sky;
        open_sky_kept += m[p];
      }
    }
  }
  ASSERT_GT(building, 50);
  EXPECT_EQ(building_kept, 0);
  ASSERT_GT(open_sky, 2000);
  EXPECT_EQ(open_sky_kept, open_sky);
  fs::remove_all(dir);
}

TEST(SkyMaskTest, TheSessionsOwnMaskOverridesSegmentation) {
  const fs::path dir = TempDir("skymask_user");
  const fs::path sdir = dir / "session";
  const Session s = MakeSession(sdir, {{"slot0/sky/view0", "masks/sky0.png"}, {"*", "auto"}});
  fs::create_directories(sdir / "masks");
  Image png(kSize, kSize, 1, PixelUnits::kDigital);
  for (int y = 0; y < kSize; ++y)
    for (int x = 0; x < kSize / 2; ++x) png.at(x, y, 0) = 255;  // the left half is sky
  WriteImage((sdir / "masks/sky0.png").string(), png, StoredType::kUint8);
  HdrGroup g = SkyPhoto();
  g.valid[5 * kSize + 7] = 0;
  std::string source;
  const std::vector<uint8_t> m =
      SkyMaskFor(s, g, Eigen::Vector3d(0, -1, 1).normalized(), SkySegmentOptions{}, &source);
  EXPECT_EQ(source, (sdir / "masks/sky0.png").string());
  for (int y = 0; y < kSize; ++y)
    for (int x = 0; x < kSize; ++x)
      ASSERT_EQ(m[y * kSize + x], x < kSize / 2 && !(x == 7 && y == 5) ? 1 : 0) << x << "," << y;
  // Another group of the same session takes the "*" entry.
  HdrGroup other = SkyPhoto();
  other.name = "slot1/sky/view0";
  SkyMaskFor(s, other, Eigen::Vector3d(0, -1, 1).normalized(), SkySegmentOptions{}, &source);
  EXPECT_EQ(source, "automatic");
  fs::remove_all(dir);
}

TEST(SkyMaskTest, TheSlotsSkyPhotosAreFittedTogether) {
  const fs::path dir = TempDir("skymask_slot");
  const fs::path sdir = dir / "session";
  const Session s = MakeSession(sdir, {{"slot0/sky/view0", "left.png"}});
  Image png(kSize, kSize, 1, PixelUnits::kDigital);
  for (int y = 0; y < kSize; ++y)
    for (int x = 0; x < kSize / 2; ++x) png.at(x, y, 0) = 255;
  WriteImage((sdir / "left.png").string(), png, StoredType::kUint8);
  CalibResult calib;
  HdrGroup up = SkyPhoto();
  HdrGroup west = SkyPhoto();
  west.name = "slot0/sky/view1";
  west.pose = Pose::Level(Eigen::Vector3d::Zero(), 270, 30);
  calib.groups[up.name] = up;
  calib.groups[west.name] = west;
  const Eigen::Vector3d sun = Eigen::Vector3d(0, -1, 1).normalized();
  std::string sources;
  const std::vector<SkySample> both =
      SlotSkySamples(s, calib, 0, sun, SkySegmentOptions{}, SkySampleOptions{}, &sources);
  EXPECT_EQ(sources, "slot0/sky/view0: " + (sdir / "left.png").string() + ", slot0/sky/view1: all");
  const std::vector<uint8_t> left = SkyMaskFor(s, up, sun, SkySegmentOptions{});
  const size_t n0 =
      ExtractSkySamples(up.radiance, &left, up.intrinsics, up.pose, sun, SkySampleOptions{}).size();
  const size_t n1 = ExtractSkySamples(west.radiance, &west.valid, west.intrinsics, west.pose, sun,
                                      SkySampleOptions{})
                        .size();
  ASSERT_GT(n0, 100u);
  ASSERT_GT(n1, 100u);
  EXPECT_EQ(both.size(), n0 + n1);
  // A slot without a sky photo has nothing to fit.
  try {
    SlotSkySamples(s, calib, 1, sun, SkySegmentOptions{}, SkySampleOptions{});
    ADD_FAILURE() << "slot 1 has no sky photo";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("slot 1 has no sky pixels"), std::string::npos)
        << e.what();
  }
  fs::remove_all(dir);
}

TEST(SkyMaskTest, BadMasksNameTheFileOrTheSessionEntry) {
  const fs::path dir = TempDir("skymask_bad");
  const HdrGroup g = SkyPhoto();
  // Wrong size.
  const Session small = MakeSession(dir / "a", {{"slot0/sky/view0", "small.png"}});
  WriteImage((dir / "a/small.png").string(), Image(10, 10, 1, PixelUnits::kDigital, 255.f),
             StoredType::kUint8);
  const std::string e1 = ErrorOf(small, g);
  EXPECT_NE(e1.find("small.png: mask is 10x10"), std::string::npos) << e1;
  // Missing file.
  const Session missing = MakeSession(dir / "b", {{"slot0/sky/view0", "nothere.png"}});
  EXPECT_NE(ErrorOf(missing, g).find("nothere.png"), std::string::npos) << ErrorOf(missing, g);
  // A path that leaves the session folder.
  const Session outside = MakeSession(dir / "c", {{"slot0/sky/view0", "../a/small.png"}});
  EXPECT_NE(ErrorOf(outside, g), "");
  EXPECT_FALSE(ErrorOf(outside, g).find("mask is") != std::string::npos) << ErrorOf(outside, g);
  // Not a file name: session.json itself is refused, naming the key.
  const std::string number = LoadErrorOf(dir / "d", {{"slot0/sky/view0", 5}});
  EXPECT_NE(number.find("session.json"), std::string::npos) << number;
  EXPECT_NE(number.find("extra.sky_masks.slot0/sky/view0"), std::string::npos) << number;
  // A photo with no sky at all (all grey) cannot be segmented: the error says what to do.
  HdrGroup grey = g;
  std::fill(grey.radiance.data.begin(), grey.radiance.data.end(), 0.f);
  const Session plain = MakeSession(dir / "e", {{"slot0/sky/view0", "auto"}});
  EXPECT_NE(ErrorOf(plain, grey).find("rouen import --sky-mask FILE"), std::string::npos)
      << ErrorOf(plain, grey);
  // sky_masks must be an object.
  const std::string list = LoadErrorOf(dir / "f", nlohmann::json::array({"a.png"}));
  EXPECT_NE(list.find("extra.sky_masks must be an object"), std::string::npos) << list;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
