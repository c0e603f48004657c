// End-to-end tests of `rouen import`: run the binary on real photo sets and on synthetic
// folders, then read the session back.
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "calib/colmap_test_support.h"
#include "core/angles.h"
#include "core/error.h"
#include "core/exif.h"
#include "core/files.h"
#include "core/geodesy.h"
#include "core/image.h"
#include "core/mesh.h"
#include "core/session.h"
#include "core/solar.h"
#include "core/time.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using rouen::cli_test::Q;
using rouen::cli_test::Result;
using rouen::cli_test::RunRouen;
using rouen::cli_test::TempDir;

void WriteText(const fs::path& p, const std::string& s) { std::ofstream(p) << s; }

// Names in `dir` that start with `prefix` (the session folder or its temporary twin).
std::vector<std::string> Leftovers(const fs::path& dir, const std::string& prefix) {
  std::vector<std::string> out;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string n = e.path().filename().string();
    if (n.rfind(prefix, 0) == 0) out.push_back(n);
  }
  return out;
}

// A small 8-bit JPEG with EXIF attributes written through OpenImageIO.
void WriteJpeg(const fs::path& path, int w, int h, float exposure_s, const std::string& datetime,
               const std::string& offset = "") {
  OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::UINT8);
  if (exposure_s > 0) spec.attribute("ExposureTime", exposure_s);
  if (!datetime.empty()) spec.attribute("Exif:DateTimeOriginal", datetime);
  if (!offset.empty()) spec.attribute("Exif:OffsetTimeOriginal", offset);
  spec.attribute("Make", "Acme");
  spec.attribute("Model", "Box 1");
  std::vector<unsigned char> px(static_cast<size_t>(w) * h * 3);
  for (size_t i = 0; i < px.size(); ++i) px[i] = static_cast<unsigned char>(40 + i % 150);
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(path.string(), spec));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
  ASSERT_TRUE(out->close());
}

void WritePng(const fs::path& path, int w, int h, float value) {
  Image im(w, h, 3, PixelUnits::kDigital);
  for (size_t i = 0; i < im.data.size(); ++i) im.data[i] = std::fmod(value + i * 7.f, 256.f);
  WriteImage(path.string(), im, StoredType::kUint8);
}

std::map<int64_t, nlohmann::json> SourcesById(const Session& s) {
  std::map<int64_t, nlohmann::json> out;
  for (const auto& f : s.info().extra.at("import").at("frames")) out[f.at("id").get<int64_t>()] = f;
  return out;
}

fs::path SharedHdr(const std::string& set) {
  return fs::path(ROUEN_SHARED_DIR) / "data" / "hdr" / set;
}

TEST(ImportTest, StLouisExposuresAndTimesFromExif) {
  const fs::path photos = SharedHdr("stlouis_arch");
  if (!fs::is_directory(photos)) GTEST_SKIP() << photos << " is absent (no ../shared data)";
  const fs::path dir = TempDir("stlouis");
  const fs::path out = dir / "session";
  // Site from the photos' GPS tags (38 deg 37.566' N, 90 deg 11.467' W, 147 m).
  const Site site{38.6261, -90.1911, 147};
  Result r =
      RunRouen("import --photos " + Q(photos) + " --site 38.6261,-90.1911,147 --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  // Taken after dark: imported (a response calibration may use them), and said.
  EXPECT_NE(r.out.find("warning: 4 of the photos were taken with the sun below the horizon"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("img_15.jpg (2008-06-01T03:44:54Z, sun -2"), std::string::npos) << r.out;
  const Session s = Session::Load(out);
  ASSERT_EQ(s.frames().size(), 4u);
  EXPECT_NEAR(s.info().site.lat_deg, site.lat_deg, 1e-12);
  EXPECT_NEAR(s.info().site.lon_deg, site.lon_deg, 1e-12);
  // The README's EXIF table and sha256 list.
  const std::map<std::string, double> readme_exposure = {{"img_0.033.jpg", 1.0 / 30},
                                                         {"img_0.25.jpg", 0.25},
                                                         {"img_2.5.jpg", 2.5},
                                                         {"img_15.jpg", 15}};
  const std::map<std::string, std::string> readme_sha = {
      {"img_0.033.jpg", "12bc79a64c224daedf4d1ab869db4bd729ce046b8035e72752c1fce51f2b22eb"},
      {"img_0.25.jpg", "e9e346585070336d2e166ac91a39337ab6f6a44bb825e37ed9708821d5e31ffd"},
      {"img_15.jpg", "73aee8c6213475a2926074628df9549663d24ead9e011a21f93f6d1ad802e8c8"},
      {"img_2.5.jpg", "cb1ebbd2cba0959b0faef1ba08e284a91a94c699ff6a08254bf321589626d8b1"}};
  const auto sources = SourcesById(s);
  // README: taken 2008-05-31 22:44-22:51 local (CDT, UTC-5).
  const UtcTime earliest = ParseIso8601("2008-05-31T22:44:00-05:00");
  const UtcTime latest = ParseIso8601("2008-05-31T22:52:00-05:00");
  std::map<std::string, int> seen;
  for (const FrameRecord& f : s.frames()) {
    const std::string name = sources.at(f.id).at("source").get<std::string>();
    ++seen[name];
    const PhotoMetadata m = ReadPhotoMetadata((photos / name).string());
    ASSERT_TRUE(m.exposure_s) << name;
    EXPECT_EQ(f.exposure_s, *m.exposure_s) << name;
    EXPECT_EQ(f.exposure_s, readme_exposure.at(name)) << name;
    EXPECT_FALSE(f.hdr);
    EXPECT_EQ(f.target, Target::kArchitecture);
    EXPECT_EQ(f.group, "slot0/architecture/view0");
    EXPECT_EQ(f.slot, 0);
    ASSERT_TRUE(m.f_number);
    EXPECT_EQ(f.aperture_f, *m.f_number);
    EXPECT_NE(f.device.find("PowerShot S3"), std::string::npos) << f.device;
    const auto utc = CaptureUtc(m, std::nullopt);
    ASSERT_TRUE(utc) << name << ": the set's DateTimeOriginal carries an offset";
    EXPECT_EQ(f.utc, *utc) << name;
    EXPECT_GE(f.utc, earliest) << name;
    EXPECT_LE(f.utc, latest) << name;
    const SunPosition sun = ComputeSunPosition(f.utc, site);
    EXPECT_NEAR(f.sun_azimuth_deg, sun.azimuth_deg, 1e-9);
    EXPECT_NEAR(f.sun_elevation_deg, sun.elevation_deg, 1e-9);
    EXPECT_LT(f.sun_elevation_deg, 0) << "a night shot";
    EXPECT_EQ(Sha256File(s.PathOf(f)), f.sha256);
    EXPECT_EQ(sources.at(f.id).at("source_sha256").get<std::string>(), readme_sha.at(name));
    EXPECT_FALSE(f.intrinsics);
    EXPECT_FALSE(f.pose);
  }
  EXPECT_EQ(seen.size(), 4u);
  // Pixels are the JPEG's decoded values, unchanged (8-bit PNG is lossless).
  const FrameRecord& f0 = s.frames().front();
  const Image stored = s.LoadFrame(f0);
  const Image source =
      ReadImage((photos / sources.at(f0.id).at("source").get<std::string>()).string());
  ASSERT_EQ(stored.data.size(), source.data.size());
  EXPECT_TRUE(stored.data == source.data);
  EXPECT_TRUE(Leftovers(dir, "session.tmp").empty());
  fs::remove_all(dir);
}

TEST(ImportTest, MemorialWithListedExposuresAndTimes) {
  const fs::path photos = SharedHdr("memorial");
  if (!fs::is_directory(photos)) GTEST_SKIP() << photos << " is absent (no ../shared data)";
  const fs::path dir = TempDir("memorial");
  // The README's table: memorial0061 is 32 s, each next file one stop shorter. The list gives
  // the exposures as fractions and an ISO time per line (the PNGs carry no EXIF).
  const char* readme[] = {"32",  "16",   "8",    "4",    "2",     "1",     "1/2",   "1/4",
                          "1/8", "1/16", "1/32", "1/64", "1/128", "1/256", "1/512", "1/1024"};
  std::string list;
  const UtcTime t0 = ParseIso8601("1997-03-01T11:00:00-08:00");
  for (int i = 0; i < 16; ++i)
    list += "memorial00" + std::to_string(61 + i) + ".png " + readme[i] + " " +
            t0.PlusSeconds(60.0 * i).Iso8601(0) + "\n";
  WriteText(dir / "list.txt", list);
  const fs::path out = dir / "s";
  Result r = RunRouen("import --photos " + Q(photos) + " --list " + Q(dir / "list.txt") +
                      " --site 37.4275,-122.1697,30 --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  const Session s = Session::Load(out);
  ASSERT_EQ(s.frames().size(), 16u);
  const auto sources = SourcesById(s);
  const Site site{37.4275, -122.1697, 30};
  for (const FrameRecord& f : s.frames()) {
    const std::string name = sources.at(f.id).at("source").get<std::string>();
    const int i = std::stoi(name.substr(8, 4)) - 61;
    ASSERT_GE(i, 0);
    ASSERT_LT(i, 16);
    EXPECT_DOUBLE_EQ(f.exposure_s, std::ldexp(32.0, -i)) << name;
    EXPECT_EQ(f.utc, t0.PlusSeconds(60.0 * i)) << name;
    EXPECT_EQ(sources.at(f.id).at("time_source"), "list");
    EXPECT_EQ(f.group, "slot0/architecture/view0");
    EXPECT_EQ(f.gain, 1.0) << "no ISO in the PNGs";
    const SunPosition sun = ComputeSunPosition(f.utc, site);
    EXPECT_NEAR(f.sun_elevation_deg, sun.elevation_deg, 1e-9);
    EXPECT_EQ(Sha256File(s.PathOf(f)), f.sha256);
  }
  const Image im = s.LoadFrame(s.frames()[0]);
  EXPECT_EQ(im.width, 512);
  EXPECT_EQ(im.height, 768);
  EXPECT_TRUE(im.data ==
              ReadImage((photos / sources.at(1).at("source").get<std::string>()).string()).data);

  // The set's own two-column exposures.txt works too, with --time for the missing times.
  const fs::path out2 = dir / "s2";
  r = RunRouen("import --photos " + Q(photos) + " --list " + Q(photos / "exposures.txt") +
               " --time 1997-03-01T12:00:00-08:00 --site 37.4275,-122.1697,30 --out " + Q(out2));
  ASSERT_EQ(r.code, 0) << r.out;
  const Session s2 = Session::Load(out2);
  ASSERT_EQ(s2.frames().size(), 16u);
  for (const FrameRecord& f : s2.frames()) EXPECT_EQ(f.utc, ParseIso8601("1997-03-01T20:00:00Z"));
  fs::remove_all(dir);
}

TEST(ImportTest, TimezoneSlotsGroupsPosesAndExr) {
  const fs::path dir = TempDir("synthetic");
  const fs::path photos = dir / "photos";
  fs::create_directories(photos);
  // Morning bracket (two views by group), then one photo 2 h later: two slots.
  WriteJpeg(photos / "a1.jpg", 32, 24, 1.f / 100, "2024:06:21 09:00:00");
  WriteJpeg(photos / "a2.jpg", 32, 24, 1.f / 25, "2024:06:21 09:00:02");
  WriteJpeg(photos / "b1.jpg", 40, 20, 1.f / 50, "2024:06:21 09:01:00");
  WriteJpeg(photos / "c1.jpg", 32, 24, 1.f / 200, "2024:06:21 11:00:00");
  // An EXR: an HDR frame as it is, no exposure needed; its own time from the list.
  Image hdr(16, 8, 3, PixelUnits::kRadiance);
  for (size_t i = 0; i < hdr.data.size(); ++i) hdr.data[i] = 0.25f * (i % 9);
  WriteImage((photos / "sky.exr").string(), hdr, StoredType::kFloat);
  WriteText(dir / "list.txt",
            "a1.jpg - group=east\n"
            "a2.jpg - group=east\n"
            "b1.jpg 1/50 group=west\n"
            "sky.exr - 2024-06-21T09:00:30+02:00 target=sky\n");
  WriteText(dir / "poses.json", R"({"a1.jpg": {
      "intrinsics": {"projection": "pinhole", "width": 32, "height": 24,
                     "fx": 30, "fy": 30, "cx": 16, "cy": 12},
      "pose": {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "position": [1, 2, 3]}}})");
  const fs::path out = dir / "s";
  Result r = RunRouen("import --photos " + Q(photos) + " --list " + Q(dir / "list.txt") +
                      " --poses " + Q(dir / "poses.json") +
                      " --timezone +02:00 --site 48.8566,2.3522,35 --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  const Session s = Session::Load(out);
  ASSERT_EQ(s.frames().size(), 5u);
  const auto sources = SourcesById(s);
  std::map<std::string, FrameRecord> by;
  for (const FrameRecord& f : s.frames()) by[sources.at(f.id).at("source")] = f;
  EXPECT_EQ(by["a1.jpg"].utc, ParseIso8601("2024-06-21T07:00:00Z"));
  EXPECT_EQ(by["c1.jpg"].utc, ParseIso8601("2024-06-21T09:00:00Z"));
  EXPECT_EQ(by["sky.exr"].utc, ParseIso8601("2024-06-21T07:00:30Z"));
  EXPECT_EQ(by["a1.jpg"].group, by["a2.jpg"].group);
  EXPECT_EQ(by["a1.jpg"].group, "slot0/architecture/view0");
  EXPECT_EQ(by["b1.jpg"].group, "slot0/architecture/view1");
  EXPECT_EQ(by["c1.jpg"].group, "slot1/architecture/view0");
  EXPECT_EQ(by["c1.jpg"].slot, 1);
  EXPECT_EQ(by["sky.exr"].group, "slot0/sky/view0");
  EXPECT_EQ(by["sky.exr"].target, Target::kSky);
  EXPECT_TRUE(by["sky.exr"].hdr);
  EXPECT_FALSE(by["a1.jpg"].hdr);
  // OpenImageIO's writer turns the float 0.04 into a rational with about 5 digits.
  EXPECT_NEAR(by["a2.jpg"].exposure_s, 1.0 / 25, 1e-4 / 25);
  EXPECT_NEAR(by["b1.jpg"].exposure_s, 1.0 / 50, 1e-15);
  ASSERT_TRUE(by["a1.jpg"].intrinsics);
  EXPECT_EQ(by["a1.jpg"].intrinsics->fx, 30);
  ASSERT_TRUE(by["a1.jpg"].pose);
  EXPECT_EQ(by["a1.jpg"].pose->position.z(), 3);
  EXPECT_FALSE(by["a2.jpg"].pose);
  const Image back = s.LoadFrame(by["sky.exr"]);
  ASSERT_EQ(back.data.size(), hdr.data.size());
  for (size_t i = 0; i < hdr.data.size(); ++i) EXPECT_EQ(back.data[i], hdr.data[i]);
  fs::remove_all(dir);
}

// A COLMAP model's images.txt line for a camera at `site_pose`, the model's frame being the
// site's under x_site = s rot x_model + t.
std::string ColmapImageLine(int id, const std::string& name, const Pose& site_pose,
                            const Eigen::Matrix3d& rot, double s, const Eigen::Vector3d& t) {
  const Pose in_model{rot.transpose() * site_pose.rotation,
                      rot.transpose() * (site_pose.position - t) / s};
  return std::to_string(id) + " " + ColmapPoseText(in_model) + " 1 " + name + "\n\n";
}

// A JPEG carrying the GPS position `p` as EXIF writes it (degrees, minutes, seconds, hemisphere).
void WriteJpegWithGps(const fs::path& path, const Site& p) {
  OIIO::ImageSpec spec(32, 24, 3, OIIO::TypeDesc::UINT8);
  spec.attribute("ExposureTime", 1.f / 100);
  spec.attribute("Exif:DateTimeOriginal", "2024:06:21 09:00:00");
  const auto dms = [](double deg, float out[3]) {
    deg = std::abs(deg);
    out[0] = static_cast<float>(std::floor(deg));
    out[1] = static_cast<float>(std::floor((deg - out[0]) * 60));
    out[2] = static_cast<float>((deg - out[0] - out[1] / 60.0) * 3600);
  };
  float lat[3], lon[3];
  dms(p.lat_deg, lat);
  dms(p.lon_deg, lon);
  spec.attribute("GPS:Latitude", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 3), lat);
  spec.attribute("GPS:LatitudeRef", p.lat_deg < 0 ? "S" : "N");
  spec.attribute("GPS:Longitude", OIIO::TypeDesc(OIIO::TypeDesc::FLOAT, 3), lon);
  spec.attribute("GPS:LongitudeRef", p.lon_deg < 0 ? "W" : "E");
  spec.attribute("GPS:Altitude", static_cast<float>(p.height_m));
  std::vector<unsigned char> px(32 * 24 * 3, 90);
  auto out = OIIO::ImageOutput::create(path.string());
  ASSERT_TRUE(out);
  ASSERT_TRUE(out->open(path.string(), spec));
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
  ASSERT_TRUE(out->close());
}

// Without control points, a COLMAP model is aligned by its photos' GPS (issue 32's (a)): four
// photos taken around a building, each with the position its GPS wrote, land at their site
// poses; one GPS position 40 m off (a fix from the car park) is refused by the default 5 m
// bound with the residual named, and accepted when the user raises the bound.
TEST(ImportTest, ColmapModelAlignedByThePhotosGps) {
  const fs::path dir = TempDir("colmap_gps");
  const fs::path photos = dir / "photos";
  fs::create_directories(photos);
  const Site site{48.8566, 2.3522, 35};
  const LocalFrame frame(site);
  const double s = 0.2, c = std::cos(1.1), n = std::sin(1.1);
  const Eigen::Matrix3d rot = (Eigen::Matrix3d() << c, -n, 0, n, c, 0, 0, 0, 1).finished();
  const Eigen::Vector3d t(-3, 8, 2);
  const std::vector<Pose> truth = {
      Pose::LookAt({30, -40, 1.6}, {0, 0, 10}), Pose::LookAt({-20, -35, 1.7}, {0, 0, 12}),
      Pose::LookAt({-45, 10, 1.5}, {0, 0, 8}), Pose::LookAt({25, 30, 1.8}, {0, 0, 9})};
  std::string images, list;
  for (size_t i = 0; i < truth.size(); ++i) {
    const std::string name = "p" + std::to_string(i) + ".jpg";
    WriteJpegWithGps(photos / name, frame.ToGeodetic(truth[i].position));
    images += ColmapImageLine(static_cast<int>(i) + 1, name, truth[i], rot, s, t);
    list += name + " - group=g" + std::to_string(i) + "\n";
  }
  WriteText(dir / "list.txt", list);
  fs::create_directories(dir / "sparse");
  WriteText(dir / "sparse" / "cameras.txt", "1 PINHOLE 32 24 30 30 16 12\n");
  WriteText(dir / "sparse" / "images.txt", images);
  const std::string base = "import --photos " + Q(photos) + " --list " + Q(dir / "list.txt") +
                           " --colmap " + Q(dir / "sparse") +
                           " --timezone +02:00 --site 48.8566,2.3522,35";
  Result r = RunRouen(base + " --out " + Q(dir / "s"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("4 photos posed from the COLMAP model (alignment residual RMS 0.00"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("over 4 GPS positions"), std::string::npos) << r.out;
  const Session session = Session::Load(dir / "s");
  const auto sources = SourcesById(session);
  ASSERT_EQ(session.frames().size(), truth.size());
  for (const FrameRecord& f : session.frames()) {
    const std::string src = sources.at(f.id).at("source");
    const Pose& want = truth[src[1] - '0'];
    ASSERT_TRUE(f.pose) << src;
    // EXIF's float32 seconds of arc: about 1 mm on the ground.
    EXPECT_LT((f.pose->position - want.position).norm(), 0.01) << src;
    EXPECT_LT((f.pose->rotation - want.rotation).norm(), 1e-3) << src;
  }

  // One photo's GPS 40 m east of where it stood.
  Site off = frame.ToGeodetic(truth[2].position + Eigen::Vector3d(40, 0, 0));
  WriteJpegWithGps(photos / "p2.jpg", off);
  r = RunRouen(base + " --out " + Q(dir / "t"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("the GPS positions in 4 photos' EXIF: the alignment of"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("beyond --colmap-max-rms-m 5"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "t"));
  r = RunRouen(base + " --colmap-max-rms-m 50 --out " + Q(dir / "t"));
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

// Photos posed by photogrammetry: a COLMAP sparse model in its own frame (here the site's
// turned 30 degrees, scaled by 0.2 and moved) registered two of the three photos; control
// points known in both frames align it, and each registered photo lands at its site pose.
// A control point in the wrong frame is refused with the residual named.
TEST(ImportTest, ColmapModelAlignedByControlPoints) {
  const fs::path dir = TempDir("colmap");
  const fs::path photos = dir / "photos";
  fs::create_directories(photos / "day");
  WriteJpeg(photos / "day" / "p1.jpg", 32, 24, 1.f / 100, "2024:06:21 09:00:00");
  WriteJpeg(photos / "day" / "p2.jpg", 32, 24, 1.f / 100, "2024:06:21 09:00:05");
  WriteJpeg(photos / "day" / "pano.jpg", 64, 32, 1.f / 100, "2024:06:21 09:00:09");
  WriteText(dir / "list.txt",
            "day/p1.jpg - group=a\nday/p2.jpg - group=b\nday/pano.jpg - target=landscape\n");
  // site = s R x_model + t
  const double s = 5.0, c = std::cos(kPi / 6), n = std::sin(kPi / 6);
  const Eigen::Matrix3d rot = (Eigen::Matrix3d() << c, -n, 0, n, c, 0, 0, 0, 1).finished();
  const Eigen::Vector3d t(12, -7, 0.5);
  auto to_model = [&](const Eigen::Vector3d& site) -> Eigen::Vector3d {
    return rot.transpose() * (site - t) / s;
  };
  const Pose truth[2] = {Pose::LookAt({30, -40, 1.6}, {0, 0, 10}),
                         Pose::LookAt({-20, -35, 1.7}, {0, 0, 12})};
  std::string images;
  for (int i = 0; i < 2; ++i)
    images += ColmapImageLine(i + 1, "day/p" + std::to_string(i + 1) + ".jpg", truth[i], rot, s, t);
  fs::create_directories(dir / "sparse");
  WriteText(dir / "sparse" / "cameras.txt", "1 OPENCV 32 24 30 31 16 12 -0.1 0.01 0 0\n");
  WriteText(dir / "sparse" / "images.txt", images);
  std::string control = "# surveyed corners\nx,y,z,east_m,north_m,up_m\n";
  for (const Eigen::Vector3d& site : {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(10, 0, 0),
                                      Eigen::Vector3d(0, 20, 0), Eigen::Vector3d(0, 0, 15)}) {
    const Eigen::Vector3d m = to_model(site);
    char line[200];
    std::snprintf(line, sizeof line, "%.17g,%.17g,%.17g,%g,%g,%g\n", m.x(), m.y(), m.z(), site.x(),
                  site.y(), site.z());
    control += line;
  }
  WriteText(dir / "control.csv", control);
  WriteText(dir / "cameras.json", R"({"day/pano.jpg": {
      "intrinsics": {"projection": "equirect", "width": 64, "height": 32},
      "pose": {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "position": [0, -30, 1.6]}}})");
  const std::string base = "import --photos " + Q(photos) + " --list " + Q(dir / "list.txt") +
                           " --colmap " + Q(dir / "sparse") + " --cameras " +
                           Q(dir / "cameras.json") + " --timezone +02:00 --site 48.8566,2.3522,35";
  Result r =
      RunRouen(base + " --colmap-control " + Q(dir / "control.csv") + " --out " + Q(dir / "s"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("2 photos posed from the COLMAP model (alignment residual RMS 0.000 m"),
            std::string::npos)
      << r.out;
  const Session session = Session::Load(dir / "s");
  const auto sources = SourcesById(session);
  int posed = 0;
  for (const FrameRecord& f : session.frames()) {
    const std::string src = sources.at(f.id).at("source");
    ASSERT_TRUE(f.pose && f.intrinsics) << src;
    if (src == "day/pano.jpg") {
      EXPECT_EQ(f.intrinsics->projection, Projection::kEquirect);
      continue;
    }
    const Pose& want = truth[src == "day/p1.jpg" ? 0 : 1];
    EXPECT_LT((f.pose->position - want.position).norm(), 1e-9) << src;
    EXPECT_LT((f.pose->rotation - want.rotation).norm(), 1e-9) << src;
    EXPECT_EQ(f.intrinsics->fy, 31);
    EXPECT_EQ(f.intrinsics->k1, -0.1);
    ++posed;
  }
  EXPECT_EQ(posed, 2);

  // One control point given in the site's frame on both sides: refused, naming the residual.
  std::string wrong = control;
  wrong += "1,1,1,1,1,1\n";
  WriteText(dir / "wrong.csv", wrong);
  r = RunRouen(base + " --colmap-control " + Q(dir / "wrong.csv") + " --out " + Q(dir / "t"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find((dir / "wrong.csv").string() + ": the alignment of "), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("beyond --colmap-max-rms-m"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "t"));
  // Without control points, and without GPS in the photos, the model's frame is not the
  // site's: refused, naming a photo without GPS.
  r = RunRouen(base + " --out " + Q(dir / "t"));
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("0 of the photos it registered carry a GPS position in EXIF (day/p"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("or --colmap-control"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

// One panorama from the ground is the landscape and the sky photo of its slot: listed with
// target=landscape+sky it is imported once per target, the same pixels and time in both.
TEST(ImportTest, OnePhotoForTwoTargets) {
  const fs::path dir = TempDir("twotargets");
  const fs::path photos = dir / "photos";
  fs::create_directories(photos);
  Image pano(16, 8, 3, PixelUnits::kRadiance);
  for (size_t i = 0; i < pano.data.size(); ++i) pano.data[i] = 0.5f + 0.125f * (i % 7);
  WriteImage((photos / "pano.exr").string(), pano, StoredType::kFloat);
  WriteImage((photos / "arch.exr").string(), pano, StoredType::kFloat);
  WriteText(dir / "list.txt",
            "pano.exr 1 2024-06-21T07:00:00Z group=pano target=landscape+sky\n"
            "arch.exr 1 2024-06-21T07:00:10Z group=front\n");
  const fs::path out = dir / "s";
  Result r = RunRouen("import --photos " + Q(photos) + " --list " + Q(dir / "list.txt") +
                      " --site 48.8566,2.3522,35 --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  const Session s = Session::Load(out);
  ASSERT_EQ(s.frames().size(), 3u);
  const auto sources = SourcesById(s);
  std::map<Target, FrameRecord> pano_by;
  for (const FrameRecord& f : s.frames())
    if (sources.at(f.id).at("source") == "pano.exr") pano_by[f.target] = f;
  ASSERT_EQ(pano_by.size(), 2u);
  ASSERT_TRUE(pano_by.count(Target::kLandscape) && pano_by.count(Target::kSky));
  EXPECT_EQ(pano_by[Target::kLandscape].group, "slot0/landscape/view0");
  EXPECT_EQ(pano_by[Target::kSky].group, "slot0/sky/view0");
  EXPECT_EQ(pano_by[Target::kSky].utc, pano_by[Target::kLandscape].utc);
  for (const auto& [target, f] : pano_by) {
    const Image back = s.LoadFrame(f);
    ASSERT_EQ(back.data.size(), pano.data.size());
    for (size_t i = 0; i < pano.data.size(); ++i) EXPECT_EQ(back.data[i], pano.data[i]);
  }
  // A target named twice, an empty one, or an unknown one is refused by line.
  for (const auto& [target, needle] :
       {std::pair{"sky+sky", "list.txt:1: target=sky+sky: target 'sky' named twice"},
        std::pair{"landscape+", "list.txt:1: target=landscape+: expected target=T or target=T+T"},
        std::pair{"landscape+roof", "list.txt:1:"}}) {
    SCOPED_TRACE(target);
    WriteText(dir / "list.txt",
              std::string("pano.exr 1 2024-06-21T07:00:00Z target=") + target + "\n");
    r = RunRouen("import --photos " + Q(photos) + " --list " + Q(dir / "list.txt") +
                 " --site 48.8566,2.3522,35 --out " + Q(dir / "bad"));
    EXPECT_EQ(r.code, 1) << r.out;
    EXPECT_NE(r.out.find(needle), std::string::npos) << r.out;
    EXPECT_FALSE(fs::exists(dir / "bad"));
  }
  fs::remove_all(dir);
}

// A minimal uncompressed 16-bit Bayer (RGGB) DNG of a uniform grey field: black level 256,
// white level 4095, stored value black + level * (white - black), identity colour matrix and
// a neutral as-shot white balance, with ExposureTime, FNumber and ISO in an EXIF sub-IFD.
void WriteDng(const fs::path& path, int w, int h, double level, int exposure_den, int iso) {
  struct Tag {
    uint16_t tag, type;
    uint32_t count;
    std::vector<uint8_t> bytes;
  };
  auto u16 = [](std::vector<uint8_t>& b, uint32_t v) {
    b.push_back(v & 0xff);
    b.push_back((v >> 8) & 0xff);
  };
  auto u32 = [&](std::vector<uint8_t>& b, uint32_t v) {
    u16(b, v & 0xffff);
    u16(b, v >> 16);
  };
  std::vector<Tag> tags;
  auto shorts = [&](uint16_t tag, std::vector<uint32_t> v) {
    Tag t{tag, 3, static_cast<uint32_t>(v.size()), {}};
    for (uint32_t x : v) u16(t.bytes, x);
    tags.push_back(t);
  };
  auto longs = [&](uint16_t tag, uint32_t v) {
    Tag t{tag, 4, 1, {}};
    u32(t.bytes, v);
    tags.push_back(t);
  };
  auto ascii = [&](uint16_t tag, const std::string& s) {
    Tag t{tag, 2, static_cast<uint32_t>(s.size() + 1), {s.begin(), s.end()}};
    t.bytes.push_back(0);
    tags.push_back(t);
  };
  auto bytes = [&](uint16_t tag, std::vector<uint8_t> v) {
    tags.push_back(Tag{tag, 1, static_cast<uint32_t>(v.size()), v});
  };
  auto rationals = [&](uint16_t tag, uint16_t type, std::vector<std::pair<int, int>> v) {
    Tag t{tag, type, static_cast<uint32_t>(v.size()), {}};
    for (auto [n, d] : v) {
      u32(t.bytes, static_cast<uint32_t>(n));
      u32(t.bytes, static_cast<uint32_t>(d));
    }
    tags.push_back(t);
  };
  const uint32_t black = 256, white = 4095;
  const uint16_t value = static_cast<uint16_t>(std::lround(black + level * (white - black)));
  const uint32_t pixel_bytes = static_cast<uint32_t>(w) * h * 2;
  // EXIF sub-IFD (libraw reads exposure and ISO there).
  rationals(33434, 5, {{1, exposure_den}});
  rationals(33437, 5, {{4, 1}});
  shorts(34855, {static_cast<uint32_t>(iso)});
  std::vector<Tag> exif_tags;
  exif_tags.swap(tags);
  longs(254, 0);
  longs(256, w);
  longs(257, h);
  shorts(258, {16});
  shorts(259, {1});
  shorts(262, {32803});  // CFA
  ascii(271, "Acme");
  ascii(272, "Raw 1");
  longs(273, 0);  // strip offset, set below
  shorts(274, {1});
  shorts(277, {1});
  longs(278, h);
  longs(279, pixel_bytes);
  shorts(284, {1});
  shorts(33421, {2, 2});
  bytes(33422, {0, 1, 1, 2});
  longs(34665, 0);  // EXIF IFD offset, set below
  bytes(50706, {1, 4, 0, 0});
  ascii(50708, "Acme Raw 1");
  shorts(50714, {black});
  shorts(50717, {white});
  rationals(50721, 10, {{1, 1}, {0, 1}, {0, 1}, {0, 1}, {1, 1}, {0, 1}, {0, 1}, {0, 1}, {1, 1}});
  rationals(50728, 5, {{1, 1}, {1, 1}, {1, 1}});
  shorts(50778, {21});
  // An IFD placed at file offset `at`: entries, next-IFD 0, then its out-of-line values.
  auto serialise = [&](const std::vector<Tag>& list, uint32_t at) {
    std::vector<uint8_t> ifd, extra;
    const uint32_t ifd_size = 2 + 12 * static_cast<uint32_t>(list.size()) + 4;
    u16(ifd, static_cast<uint32_t>(list.size()));
    for (const Tag& t : list) {
      u16(ifd, t.tag);
      u16(ifd, t.type);
      u32(ifd, t.count);
      if (t.bytes.size() <= 4) {
        std::vector<uint8_t> v = t.bytes;
        v.resize(4, 0);
        ifd.insert(ifd.end(), v.begin(), v.end());
      } else {
        u32(ifd, at + ifd_size + static_cast<uint32_t>(extra.size()));
        extra.insert(extra.end(), t.bytes.begin(), t.bytes.end());
        if (extra.size() % 2) extra.push_back(0);
      }
    }
    u32(ifd, 0);
    ifd.insert(ifd.end(), extra.begin(), extra.end());
    return ifd;
  };
  const uint32_t main_size = static_cast<uint32_t>(serialise(tags, 8).size());
  const uint32_t exif_at = 8 + main_size;
  const uint32_t strip_at = exif_at + static_cast<uint32_t>(serialise(exif_tags, 0).size());
  for (Tag& t : tags) {
    if (t.tag == 273 || t.tag == 34665) {
      t.bytes.clear();
      u32(t.bytes, t.tag == 273 ? strip_at : exif_at);
    }
  }
  std::vector<uint8_t> file = {'I', 'I', 42, 0};
  u32(file, 8);
  for (const auto& part : {serialise(tags, 8), serialise(exif_tags, exif_at)})
    file.insert(file.end(), part.begin(), part.end());
  for (int i = 0; i < w * h; ++i) u16(file, value);
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(file.data()), static_cast<std::streamsize>(file.size()));
}

double MeanOf(const Image& im) {
  double s = 0;
  for (float v : im.data) s += v;
  return s / im.data.size();
}

// The linear RAW path on synthetic DNGs: a field at half the signal with twice the exposure,
// or at twice the ISO, gives the same radiance once divided by exposure x gain.
TEST(ImportTest, RawDngIsLinearHdrDividedByExposureAndGain) {
  const fs::path dir = TempDir("dng");
  const fs::path photos = dir / "photos";
  fs::create_directories(photos);
  WriteDng(photos / "r1.dng", 64, 48, 0.2, 100, 100);  // 0.2 at 1/100 s, ISO 100
  WriteDng(photos / "r2.dng", 64, 48, 0.4, 50, 100);   // 0.4 at 1/50 s, ISO 100
  WriteDng(photos / "r3.dng", 64, 48, 0.4, 100, 200);  // 0.4 at 1/100 s, ISO 200
  PhotoMetadata m;
  try {
    m = ReadPhotoMetadata((photos / "r1.dng").string());
  } catch (const Error& e) {
    GTEST_SKIP() << "this OpenImageIO/libraw cannot read the synthetic DNG: " << e.what();
  }
  EXPECT_TRUE(m.is_raw);
  ASSERT_TRUE(m.exposure_s);
  EXPECT_NEAR(*m.exposure_s, 0.01, 1e-9);
  ASSERT_TRUE(m.iso);
  EXPECT_EQ(*m.iso, 100);
  WriteText(dir / "list.txt",
            "r1.dng - 2024-06-21T09:00:00Z\nr2.dng - 2024-06-21T09:00:01Z\n"
            "r3.dng - 2024-06-21T09:00:02Z\n");
  const fs::path out = dir / "s";
  Result r = RunRouen("import --photos " + Q(photos) + " --list " + Q(dir / "list.txt") +
                      " --site 48.8566,2.3522,35 --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  const Session s = Session::Load(out);
  ASSERT_EQ(s.frames().size(), 3u);
  std::map<std::string, FrameRecord> by;
  const auto sources = SourcesById(s);
  for (const FrameRecord& f : s.frames()) by[sources.at(f.id).at("source")] = f;
  EXPECT_TRUE(by["r1.dng"].hdr);
  EXPECT_NEAR(by["r2.dng"].exposure_s, 0.02, 1e-9);
  EXPECT_NEAR(by["r3.dng"].gain, 2.0, 1e-9);
  EXPECT_EQ(sources.at(by["r1.dng"].id).at("kind"), "raw");
  const double m1 = MeanOf(s.LoadFrame(by["r1.dng"]));
  const double m2 = MeanOf(s.LoadFrame(by["r2.dng"]));
  const double m3 = MeanOf(s.LoadFrame(by["r3.dng"]));
  std::printf(
      "[ measured ] DNG radiance means %.4f %.4f %.4f (signal/(t x ISO/100); 20 if "
      "white maps to 1)\n",
      m1, m2, m3);
  ASSERT_GT(m1, 0);
  // 12-bit quantisation (1/3839) and half-float storage (2^-11) bound the mismatch.
  EXPECT_NEAR(m2 / m1, 1.0, 2e-3);
  EXPECT_NEAR(m3 / m1, 1.0, 2e-3);
  fs::remove_all(dir);
}

// Each bad input: non-zero exit, a message naming the problem, and no session folder (or
// temporary folder) left behind.
TEST(ImportTest, BadInputsFailCleanly) {
  const fs::path dir = TempDir("bad");
  const fs::path good = dir / "good";
  fs::create_directories(good);
  WriteJpeg(good / "g1.jpg", 16, 12, 0.01f, "2024:06:21 09:00:00", "+02:00");
  const std::string site = " --site 48.8566,2.3522,35";
  auto expect_fail = [&](const std::string& args, const std::string& needle) {
    SCOPED_TRACE(args);
    Result r = RunRouen("import " + args + " --out " + Q(dir / "out"));
    EXPECT_NE(r.code, 0) << r.out;
    EXPECT_EQ(r.code, 1) << "a clear error, not an internal one: " << r.out;
    EXPECT_NE(r.out.find(needle), std::string::npos) << r.out;
    EXPECT_TRUE(Leftovers(dir, "out").empty());
  };
  expect_fail("--photos " + Q(dir / "nowhere") + site, "nowhere: no such photos folder");
  fs::create_directories(dir / "empty");
  expect_fail("--photos " + Q(dir / "empty") + site, "no photos found");
  expect_fail("--photos " + Q(good) + " --site 48.8,2.3", "--site");
  expect_fail("--photos " + Q(good) + " --site north,2.3,4", "latitude");
  expect_fail("--photos " + Q(good) + " --site 95,2.3,4", "latitude");
  expect_fail("--photos " + Q(good) + site + " --timezone 2h", "--timezone");

  const fs::path noexp = dir / "noexp";
  fs::create_directories(noexp);
  WritePng(noexp / "IMG_1.png", 8, 8, 10);
  expect_fail("--photos " + Q(noexp) + site,
              "IMG_1.png: no exposure time in EXIF and not in the list");
  WriteText(dir / "exp.txt", "IMG_1.png 0.5\n");
  expect_fail("--photos " + Q(noexp) + " --list " + Q(dir / "exp.txt") + site,
              "IMG_1.png: no capture time");
  WriteText(dir / "escape.txt", "../good/g1.jpg 0.5 2024-06-21T09:00:00Z\n");
  expect_fail("--photos " + Q(noexp) + " --list " + Q(dir / "escape.txt") + site,
              "leaves the photos folder");
  WriteText(dir / "badnum.txt", "IMG_1.png fast\n");
  expect_fail("--photos " + Q(noexp) + " --list " + Q(dir / "badnum.txt") + site,
              "badnum.txt:1: exposure 'fast' is not a number");

  const fs::path notz = dir / "notz";
  fs::create_directories(notz);
  WriteJpeg(notz / "n1.jpg", 16, 12, 0.01f, "2024:06:21 09:00:00");
  expect_fail("--photos " + Q(notz) + site,
              "n1.jpg: EXIF time \"2024:06:21 09:00:00\" has no "
              "UTC offset; give --timezone");

  const fs::path sizes = dir / "sizes";
  fs::create_directories(sizes);
  WriteJpeg(sizes / "s1.jpg", 16, 12, 0.01f, "2024:06:21 09:00:00", "+02:00");
  WriteJpeg(sizes / "s2.jpg", 20, 12, 0.02f, "2024:06:21 09:00:01", "+02:00");
  expect_fail("--photos " + Q(sizes) + site, "s2.jpg: size 20x12 differs from s1.jpg");

  const fs::path corrupt = dir / "corrupt";
  fs::create_directories(corrupt);
  WriteText(corrupt / "c1.jpg", "this is not a JPEG");
  expect_fail("--photos " + Q(corrupt) + site, "c1.jpg");
  fs::remove(corrupt / "c1.jpg");
  WriteText(corrupt / "c1.dng", "this is not a DNG either");
  expect_fail("--photos " + Q(corrupt) + site, "c1.dng");

  // A PNG whose header reads but whose pixel data is cut short: found only while writing
  // frames, after the first frame is already in the session; the temporary folder goes.
  const fs::path trunc = dir / "trunc";
  fs::create_directories(trunc);
  WritePng(trunc / "t0.png", 64, 64, 3);
  WritePng(trunc / "t1.png", 64, 64, 9);
  {
    std::string bytes = ReadFileToString(trunc / "t1.png");
    bytes.resize(bytes.size() / 2);
    std::ofstream(trunc / "t1.png", std::ios::binary) << bytes;
  }
  WriteText(dir / "trunc.txt",
            "t0.png 0.1 2024-06-21T09:00:00Z\nt1.png 0.2 2024-06-21T09:00:01Z\n");
  expect_fail("--photos " + Q(trunc) + " --list " + Q(dir / "trunc.txt") + site, "t1.png");

  WriteText(dir / "poses.json", R"({"other.jpg": {"pose": null}})");
  expect_fail("--photos " + Q(good) + " --poses " + Q(dir / "poses.json") + site,
              "\"other.jpg\" is not one of the imported photos");
  WriteText(dir / "poses.json", R"({"g1.jpg": {"intrinsics": {"projection": "pinhole",
      "width": 99, "height": 12, "fx": 10, "fy": 10, "cx": 5, "cy": 6}}})");
  expect_fail("--photos " + Q(good) + " --poses " + Q(dir / "poses.json") + site,
              "intrinsics are for 99x12");

  // An existing non-empty output folder is refused and left as it was.
  fs::create_directories(dir / "out");
  WriteText(dir / "out" / "keep.txt", "x");
  Result r = RunRouen("import --photos " + Q(good) + site + " --out " + Q(dir / "out"));
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("already exists"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(dir / "out" / "keep.txt"));
  fs::remove_all(dir / "out");

  // The good folder does import (the failures above were about their inputs).
  r = RunRouen("import --photos " + Q(good) + site + " --out " + Q(dir / "out"));
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(Session::Load(dir / "out").frames().size(), 1u);
  fs::remove_all(dir);
}

// What a user with their own photographs needs and no longer edits JSON for: the building
// model, the sky mask, ND-filtered sun photos (one density or one per channel), and the
// files `rouen calib intrinsics` / `rouen calib pose` write, by image, by group or for all.
TEST(ImportTest, ModelSkyMaskNdFiltersAndCalibFiles) {
  const fs::path dir = TempDir("userpath");
  const fs::path photos = dir / "photos";
  fs::create_directories(photos);
  WriteJpeg(photos / "w1.jpg", 32, 24, 1.f / 100, "2024:06:21 09:00:00");
  WriteJpeg(photos / "w2.jpg", 32, 24, 1.f / 25, "2024:06:21 09:00:02");
  WriteJpeg(photos / "e1.jpg", 32, 24, 1.f / 50, "2024:06:21 09:01:00");
  WriteJpeg(photos / "sun1.jpg", 32, 24, 1.f / 1000, "2024:06:21 09:02:00");
  WriteJpeg(photos / "sun2.jpg", 32, 24, 1.f / 4000, "2024:06:21 09:02:01");
  WriteJpeg(photos / "sky.jpg", 32, 24, 1.f / 500, "2024:06:21 09:03:00");
  WriteText(dir / "list.txt",
            "w1.jpg - group=west\n"
            "w2.jpg - group=west\n"
            "e1.jpg - group=east\n"
            "sun1.jpg - target=sun nd=4.5\n"
            "sun2.jpg - target=sun nd=4.4,4.5,4.9\n"
            "sky.jpg - target=sky\n");
  WriteText(dir / "lens.json", R"({"projection": "pinhole", "width": 32, "height": 24,
      "fx": 30, "fy": 30, "cx": 16, "cy": 12})");
  WriteText(dir / "west-pose.json",
            R"({"rotation": [[1,0,0],[0,1,0],[0,0,1]], "position": [-5, 0, 1.6]})");
  WriteText(dir / "cameras.json", R"({"*": {"lens": "lens.json"},
      "group=west": {"pose": "west-pose.json"},
      "e1.jpg": {"pose": {"rotation": [[1,0,0],[0,1,0],[0,0,1]], "position": [5, 0, 1.6]}}})");
  WriteText(dir / "tower.obj", "g tower\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  WriteText(dir / "houses.obj", "g house_1\nv 0 9 0\nv 0 9 3\nv 2 9 3\nf 1 2 3\n");
  WritePng(dir / "mask.png", 32, 24, 200);
  // The import's arguments with the given list and cameras files.
  const auto args = [&](const std::string& list, const std::string& cameras) {
    return "import --photos " + Q(photos) + " --list " + Q(dir / list) + " --cameras " +
           Q(dir / cameras) + " --timezone +02:00 --site 48.8566,2.3522,35";
  };
  const std::string common = args("list.txt", "cameras.json");
  const fs::path out = dir / "s";
  Result r =
      RunRouen(common + " --model " + Q(dir / "tower.obj") + " --surroundings " +
               Q(dir / "houses.obj") + " --sky-mask " + Q(dir / "mask.png") + " --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  const Session s = Session::Load(out);
  EXPECT_EQ(s.info().model, "model.obj");
  EXPECT_EQ(ReadFileToString(out / "model.obj"), ReadFileToString(dir / "tower.obj"));
  EXPECT_EQ(s.info().surroundings, "surroundings.obj");
  EXPECT_EQ(ReadFileToString(out / "surroundings.obj"), ReadFileToString(dir / "houses.obj"));
  EXPECT_EQ(s.info().sky_masks.at("*").file, "sky_mask.png");
  EXPECT_EQ(ReadFileToString(out / "sky_mask.png"), ReadFileToString(dir / "mask.png"));
  const auto sources = SourcesById(s);
  std::map<std::string, FrameRecord> by;
  for (const FrameRecord& f : s.frames()) by[sources.at(f.id).at("source")] = f;
  EXPECT_EQ(by["sun1.jpg"].nd_density, 4.5);
  EXPECT_NEAR(by["sun2.jpg"].nd_density, (4.4 + 4.5 + 4.9) / 3, 1e-12);
  EXPECT_EQ(by["w1.jpg"].nd_density, 0);
  const std::map<std::string, NdFilter>& filters = s.info().nd_filters;
  ASSERT_EQ(filters.size(), 1u);
  EXPECT_EQ(filters.begin()->second.density_rgb, (std::array<double, 3>{4.4, 4.5, 4.9}));
  // Every photo has the lens ("*"); the west group its pose file; e1 its own inline pose.
  for (const auto& [name, f] : by) {
    ASSERT_TRUE(f.intrinsics) << name;
    EXPECT_EQ(f.intrinsics->fx, 30) << name;
  }
  ASSERT_TRUE(by["w2.jpg"].pose);
  EXPECT_EQ(by["w2.jpg"].pose->position.x(), -5);
  ASSERT_TRUE(by["e1.jpg"].pose);
  EXPECT_EQ(by["e1.jpg"].pose->position.x(), 5);
  EXPECT_FALSE(by["sky.jpg"].pose);

  // --sky-mask auto is recorded as such.
  r = RunRouen(common + " --sky-mask auto --out " + Q(dir / "s2"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_TRUE(Session::Load(dir / "s2").info().sky_masks.at("*").automatic);

  // Each bad input is named, and nothing is left behind.
  const auto expect_fail = [&](const std::string& command, const std::string& phrase) {
    const Result f = RunRouen(command + " --out " + Q(dir / "bad"));
    EXPECT_EQ(f.code, 1) << command << "\n" << f.out;
    EXPECT_NE(f.out.find(phrase), std::string::npos) << command << "\n" << f.out;
    EXPECT_FALSE(fs::exists(dir / "bad")) << command;
    EXPECT_TRUE(Leftovers(dir, "bad").empty()) << command;
  };
  expect_fail(common + " --model " + Q(dir / "none.obj"), "none.obj: no such model file");
  WriteText(dir / "empty.obj", "# nothing\n");
  expect_fail(common + " --model " + Q(dir / "empty.obj"), "empty.obj");
  // Surroundings: never without the building, never sharing a block name with it.
  expect_fail(common + " --surroundings " + Q(dir / "houses.obj"),
              "houses.obj: surroundings need the building's model (--model)");
  expect_fail(
      common + " --model " + Q(dir / "tower.obj") + " --surroundings " + Q(dir / "tower.obj"),
      "tower.obj: block 'tower' is in both models (rename the group in one of them)");
  // Trees join the surroundings (after the given OBJ, a block each), or are them.
  WriteText(dir / "trees.csv", "name,x_m,y_m,height_m,crown_diameter_m\nlime,3,8,9,5\n");
  r = RunRouen(common + " --model " + Q(dir / "tower.obj") + " --surroundings " +
               Q(dir / "houses.obj") + " --trees " + Q(dir / "trees.csv") + " --out " +
               Q(dir / "s3"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("1 tree from"), std::string::npos) << r.out;
  const Session s3 = Session::Load(dir / "s3");
  EXPECT_EQ(s3.info().surroundings, "surroundings.obj");
  const std::string with_trees = ReadFileToString(dir / "s3" / "surroundings.obj");
  EXPECT_EQ(with_trees.rfind(ReadFileToString(dir / "houses.obj"), 0), 0u);
  EXPECT_EQ(ReadObj((dir / "s3" / "surroundings.obj").string()).block_names,
            (std::vector<std::string>{"house_1", "lime"}));
  EXPECT_EQ(s3.info().extra.at("import").at("trees").at("count"), 1);
  EXPECT_EQ(s3.info().trees, (std::vector<std::string>{"lime"}));
  r = RunRouen("status " + Q(dir / "s3"));
  EXPECT_NE(r.out.find("with surroundings surroundings.obj (1 tree)"), std::string::npos) << r.out;
  r = RunRouen(common + " --model " + Q(dir / "tower.obj") + " --trees " + Q(dir / "trees.csv") +
               " --out " + Q(dir / "s4"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(ReadObj((dir / "s4" / "surroundings.obj").string()).block_names,
            (std::vector<std::string>{"lime"}));
  expect_fail(common + " --trees " + Q(dir / "trees.csv"),
              "trees.csv: trees need the building's model (--model)");
  WriteText(dir / "trees2.csv", "name,x_m,y_m,height_m,crown_diameter_m\nhouse_1,3,8,9,5\n");
  expect_fail(common + " --model " + Q(dir / "tower.obj") + " --surroundings " +
                  Q(dir / "houses.obj") + " --trees " + Q(dir / "trees2.csv"),
              "trees2.csv: block 'house_1' is in both models");
  WriteText(dir / "trees2.csv", "name,x_m,y_m,height_m,crown_diameter_m\nlime,3,8,-9,5\n");
  expect_fail(common + " --model " + Q(dir / "tower.obj") + " --trees " + Q(dir / "trees2.csv"),
              "trees2.csv:2: height_m must be positive");
  WritePng(dir / "small.png", 8, 8, 200);
  expect_fail(common + " --sky-mask " + Q(dir / "small.png"), "small.png");
  WriteText(dir / "list2.txt", "sun1.jpg - target=sun nd=4.5,4\n");
  expect_fail(args("list2.txt", "cameras.json"), "list2.txt:1: nd=4.5,4: expected");
  WriteText(dir / "list2.txt", "sun1.jpg - target=sun nd=-1\n");
  expect_fail(args("list2.txt", "cameras.json"), "list2.txt:1");
  // A key given twice on a line is a contradiction, not "the last one wins".
  WriteText(dir / "list2.txt", "sun1.jpg - target=sun nd=1 nd=2\n");
  expect_fail(args("list2.txt", "cameras.json"), "list2.txt:1: nd= given twice");
  WriteText(dir / "list2.txt", "sun1.jpg - group=a target=sun group=b\n");
  expect_fail(args("list2.txt", "cameras.json"), "list2.txt:1: group= given twice");
  WriteText(dir / "cameras2.json", R"({"group=north": {"lens": "lens.json"}})");
  expect_fail(args("list.txt", "cameras2.json"), "\"group=north\": no listed photo has that group");
  WriteText(dir / "cameras2.json", R"({"*": {"lens": "missing-lens.json"}})");
  expect_fail(args("list.txt", "cameras2.json"), "missing-lens.json: no such lens file");
  WriteText(dir / "cameras2.json", R"({"*": {"lens": "../../etc/passwd"}})");
  expect_fail(args("list.txt", "cameras2.json"), "cameras2.json");
  fs::remove_all(dir);
}

TEST(ImportTest, HelpHasAnExample) {
  Result r = RunRouen("import --help");
  EXPECT_EQ(r.code, 0);
  for (const char* s :
       {"--photos", "--list", "--poses", "--site", "--timezone", "--out", "Example", "group=NAME"})
    EXPECT_NE(r.out.find(s), std::string::npos) << s;
}

}  // namespace
}  // namespace rouen
