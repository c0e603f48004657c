// End-to-end tests of the rouen CLI: run the binary as a user would and check its output,
// its files and its errors.
#include "app/cli.h"

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "app/command_list.h"
#include "core/image.h"
#include "tests/cli_util.h"

namespace {

namespace fs = std::filesystem;
using rouen::cli_test::Result;
using rouen::cli_test::RunRouen;
using rouen::cli_test::TempDir;

void WriteText(const fs::path& p, const std::string& s) { std::ofstream(p) << s; }

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::stringstream ss(s);
  std::string item;
  while (std::getline(ss, item, sep)) out.push_back(item);
  return out;
}

TEST(CliTest, HelpExplainsEveryCommand) {
  Result r = RunRouen("--help");
  EXPECT_EQ(r.code, 0);
  for (const char* c : {"demo", "capture", "devices", "calib", "hdr", "sun"})
    EXPECT_NE(r.out.find(c), std::string::npos) << c;
  Result c = RunRouen("capture --help");
  EXPECT_EQ(c.code, 0);
  EXPECT_NE(c.out.find("--resume"), std::string::npos);
}

// `rouen --help` and `rouen sun` run in the light binary (app/main.cc); every other command in
// the librouen_cli module. The light path must list exactly what the full CLI registers.
TEST(CliTest, LightStartUpListsWhatTheFullCliRegisters) {
  Result light = RunRouen("--help");
  ASSERT_EQ(light.code, 0) << light.out;
  std::string name = "rouen";
  std::vector<char*> argv = {name.data(), const_cast<char*>("--help")};
  testing::internal::CaptureStdout();
  const int code = rouen::RunCli(static_cast<int>(argv.size()), argv.data());
  std::string full = testing::internal::GetCapturedStdout();
  EXPECT_EQ(code, 0);
  // Only the program name in the usage line differs.
  const std::string usage = "Usage: ";
  const size_t at = light.out.find(usage), end = light.out.find(' ', at + usage.size());
  ASSERT_NE(at, std::string::npos) << light.out;
  light.out.replace(at + usage.size(), end - at - usage.size(), name);
  EXPECT_EQ(light.out, full);
  for (const rouen::CommandInfo& c : rouen::kCommands) {
    EXPECT_NE(full.find(c.summary), std::string::npos) << c.name;
  }
}

// The light binary does not link the camera drivers, OpenCV, OpenImageIO, Ceres or Embree:
// loading them is what makes the full CLI take ~0.3 s to start.
TEST(CliTest, TheRouenBinaryLinksNoHeavyLibrary) {
  const Result r = rouen::cli_test::RunShell("readelf -d " + std::string(ROUEN_BINARY));
  const std::string& out = r.out;
  if (r.code != 0) GTEST_SKIP() << "readelf (binutils) cannot read the binary: " << out;
  ASSERT_NE(out.find("(NEEDED)"), std::string::npos) << out;
  for (const char* heavy : {"OpenImageIO", "opencv", "camera", "aravis", "usb", "gps", "ceres",
                            "embree", "tbb", "glog"})
    EXPECT_EQ(out.find(heavy), std::string::npos) << heavy << " in\n" << out;
}

// Without the module beside it, the binary still answers `sun` and names what is missing for
// the rest.
TEST(CliTest, AMissingCommandModuleIsNamed) {
  const fs::path dir = TempDir("module");
  fs::copy_file(ROUEN_BINARY, dir / "rouen");
  const std::string rouen = rouen::cli_test::Q(dir / "rouen");
  const Result r = rouen::cli_test::RunShell(rouen + " status " + rouen::cli_test::Q(dir));
  const std::string& out = r.out;
  EXPECT_EQ(r.code, 2) << out;
  EXPECT_NE(out.find("librouen_cli.so"), std::string::npos) << out;
  EXPECT_NE(out.find((dir / "librouen_cli.so").string() + ": not found"), std::string::npos) << out;
  EXPECT_EQ(
      rouen::cli_test::RunShell(rouen + " sun --lat 0 --lon 0 --time 2026-03-20T12:00:00Z").code,
      0);
  fs::remove_all(dir);
}

TEST(CliTest, SunSingleAndJson) {
  // SPA's worked example (NREL): zenith 50.111622 deg, azimuth 194.340241 deg.
  Result r = RunRouen(
      "sun --lat 39.742476 --lon -105.1786 --height 1830.14 "
      "--time 2003-10-17T12:30:30-07:00 --pressure 820 --temperature 11 --json");
  ASSERT_EQ(r.code, 0) << r.out;
  nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_NEAR(j["azimuth_deg"].get<double>(), 194.340241, 3e-4);
  EXPECT_NEAR(j["zenith_deg"].get<double>(), 50.111622, 3e-4);
}

TEST(CliTest, SunBatchCsv) {
  fs::path dir = TempDir("sun");
  WriteText(dir / "in.csv",
            "utc,lat,lon,elev_m\n"
            "2026-08-25T20:30:00Z,37.8722,-122.2578,60\n"
            "2026-08-25T13:30:00-07:00,37.8722,-122.2578,60\n");
  Result r = RunRouen("sun --batch " + (dir / "in.csv").string());
  ASSERT_EQ(r.code, 0) << r.out;
  std::vector<std::string> lines = Split(r.out, '\n');
  ASSERT_GE(lines.size(), 3u);
  EXPECT_EQ(lines[0], "utc,lat,lon,elev_m,azimuth_deg,elevation_deg,elevation_true_deg");
  std::vector<std::string> a = Split(lines[1], ','), b = Split(lines[2], ',');
  ASSERT_EQ(a.size(), 7u);
  ASSERT_EQ(b.size(), 7u);
  // The same instant written two ways gives the same sun.
  EXPECT_EQ(a[4], b[4]);
  EXPECT_EQ(a[5], b[5]);
  // Refraction lifts the sun: apparent elevation above the airless one.
  EXPECT_GT(std::stod(a[5]), std::stod(a[6]));
  fs::remove_all(dir);
}

TEST(CliTest, SunBadInputNamesTheProblem) {
  fs::path dir = TempDir("sunbad");
  WriteText(dir / "bad.csv",
            "utc,lat,lon,elev_m\n2026-08-25T20:30:00Z,37.8,-122.2,60\n"
            "2026-13-25T20:30:00Z,37.8,-122.2,60\n");
  Result r = RunRouen("sun --batch " + (dir / "bad.csv").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("bad.csv:3"), std::string::npos) << r.out;
  Result t = RunRouen("sun --lat 37 --lon -122 --time yesterday");
  EXPECT_NE(t.code, 0);
  EXPECT_NE(t.out.find("yesterday"), std::string::npos) << t.out;
  Result z = RunRouen("sun --lat 37 --lon -122 --time 2026-08-25T12:00:00");  // no zone
  EXPECT_NE(z.code, 0);
  Result nolon = RunRouen("sun --lat 37 --time 2026-08-25T12:00:00Z");  // --lon forgotten
  EXPECT_NE(nolon.code, 0);
  EXPECT_NE(nolon.out.find("--lon"), std::string::npos) << nolon.out;
  // --batch gives every line's time and site: a --time beside it contradicts it.
  Result both =
      RunRouen("sun --batch " + (dir / "bad.csv").string() + " --time 2026-08-25T12:00:00Z");
  EXPECT_NE(both.code, 0);
  EXPECT_NE(both.out.find("--time excludes --batch"), std::string::npos) << both.out;
  fs::remove_all(dir);
}

TEST(CliTest, CalibResponseBadInput) {
  fs::path dir = TempDir("calibbad");
  // A corrupt image.
  WriteText(dir / "a.png", "this is not a png");
  WriteText(dir / "list.txt", "a.png 0.1\na.png 0.2\n");
  Result r = RunRouen("calib response --list " + (dir / "list.txt").string() + " --out " +
                      (dir / "r.json").string());
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("a.png"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "r.json"));
  // A list line without seconds, and a negative exposure.
  WriteText(dir / "list2.txt", "a.png\n");
  r = RunRouen("calib response --list " + (dir / "list2.txt").string() + " --out x.json");
  EXPECT_NE(r.out.find("list2.txt:1"), std::string::npos) << r.out;
  WriteText(dir / "list3.txt", "a.png -1\n");
  r = RunRouen("calib response --list " + (dir / "list3.txt").string() + " --out x.json");
  EXPECT_NE(r.out.find("positive"), std::string::npos) << r.out;
  // Readable images, but one exposure only, or the same exposure twice: nothing to recover
  // the curve from.
  rouen::Image im(16, 16, 3, rouen::PixelUnits::kDigital);
  for (size_t i = 0; i < im.data.size(); ++i) im.data[i] = static_cast<float>(i % 200 + 20);
  rouen::WriteImage((dir / "g.png").string(), im, rouen::StoredType::kUint8);
  WriteText(dir / "one.txt", "g.png 0.1\n");
  WriteText(dir / "same.txt", "g.png 0.1\ng.png 0.1\n");
  for (const char* list : {"one.txt", "same.txt"}) {
    r = RunRouen("calib response --list " + (dir / list).string() + " --out " +
                 (dir / "r.json").string());
    EXPECT_NE(r.code, 0) << list;
    EXPECT_NE(r.out.find("exposure"), std::string::npos) << r.out;
    EXPECT_FALSE(fs::exists(dir / "r.json"));
  }
  WriteText(dir / "two.txt", "g.png 0.1\ng.png 0.4\n");
  r = RunRouen("calib response --method newton --list " + (dir / "two.txt").string() +
               " --out x.json");
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("newton"), std::string::npos) << r.out;
  fs::remove_all(dir);
}

TEST(CliTest, CalibResponseAndHdrOnMemorial) {
  fs::path mem = fs::path(ROUEN_SHARED_DIR) / "data/hdr/memorial";
  if (!fs::exists(mem / "exposures.txt"))
    GTEST_SKIP() << "real data absent: " << mem << " (needs ../shared beside the checkout)";
  fs::path dir = TempDir("memorial");
  Result r = RunRouen("calib response --list " + (mem / "exposures.txt").string() + " --out " +
                      (dir / "response.json").string());
  ASSERT_EQ(r.code, 0) << r.out;
  nlohmann::json j = nlohmann::json::parse(std::ifstream(dir / "response.json"));
  ASSERT_EQ(j["g"].size(), 3u);
  for (const auto& ch : j["g"]) {
    ASSERT_EQ(ch.size(), 256u);
    for (size_t z = 1; z < 256; ++z) EXPECT_GE(ch[z].get<double>(), ch[z - 1].get<double>());
  }
  r = RunRouen("calib hdr --list " + (mem / "exposures.txt").string() + " --response " +
               (dir / "response.json").string() + " --out " + (dir / "m.exr").string());
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_GT(fs::file_size(dir / "m.exr"), 100000u);
  // The alternative methods: each a monotone curve, named in the report.
  for (const char* method : {"robertson", "mitsunaga"}) {
    r = RunRouen(std::string("calib response --method ") + method + " --list " +
                 (mem / "exposures.txt").string() + " --out " + (dir / "alt.json").string());
    ASSERT_EQ(r.code, 0) << r.out;
    EXPECT_NE(r.out.find("fit residual"), std::string::npos) << r.out;
    nlohmann::json alt = nlohmann::json::parse(std::ifstream(dir / "alt.json"));
    for (const auto& ch : alt["g"])
      for (size_t z = 1; z < 256; ++z) EXPECT_GT(ch[z].get<double>(), ch[z - 1].get<double>());
  }
  fs::remove_all(dir);
}

TEST(CliTest, DevicesListsAsTextAndJson) {
  Result h = RunRouen("devices --help");
  EXPECT_EQ(h.code, 0);
  EXPECT_NE(h.out.find("rig kind"), std::string::npos) << h.out;
  Result t = RunRouen("devices");
  EXPECT_EQ(t.code, 0) << t.out;
  EXPECT_NE(t.out.find("drivers in this build:"), std::string::npos) << t.out;
  Result j = RunRouen("devices --json");
  ASSERT_EQ(j.code, 0) << j.out;
  nlohmann::json parsed = nlohmann::json::parse(j.out);
  EXPECT_TRUE(parsed["drivers"].is_array());
  Result bad = RunRouen("devices --latency /dev/rouen-no-such-camera");
  EXPECT_NE(bad.code, 0);
  EXPECT_NE(bad.out.find("/dev/rouen-no-such-camera"), std::string::npos) << bad.out;
}

TEST(CliTest, FieldCaptureWithoutItsCameraFailsClearlyAndWritesNothing) {
  fs::path dir = TempDir("field_missing");
  WriteText(dir / "rig.toml",
            "[rig]\nname = \"w\"\nkind = \"uvc-webcam\"\n[site]\nlat_deg = 1\nlon_deg = 2\n"
            "[camera]\ndevice = \"/dev/rouen-no-such-video\"\n");
  Result r = RunRouen("capture --rig " + (dir / "rig.toml").string() + " --out " +
                      (dir / "s").string() + " --no-prompt");
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("/dev/rouen-no-such-video"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(dir / "s"));
  // A misspelt key is refused with its line.
  WriteText(dir / "typo.toml", "[rig]\nname = \"w\"\nkind = \"sim\"\n[camera]\nlatency = 3\n");
  Result t =
      RunRouen("capture --rig " + (dir / "typo.toml").string() + " --out " + (dir / "t").string());
  EXPECT_NE(t.code, 0);
  EXPECT_NE(t.out.find("typo.toml:5: unknown key 'latency' in [camera]"), std::string::npos)
      << t.out;
  fs::remove_all(dir);
}

}  // namespace
