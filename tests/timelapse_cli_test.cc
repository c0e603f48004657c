// rouen timelapse on a small solved scene (pipeline/export_test_util.h): the frames of a day,
// named by their times, one exposure (the day darkens towards sunset), the MP4 through ffmpeg.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>

#include "core/image.h"
#include "pipeline/export_test_util.h"
#include "pipeline/timelapse.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;
using cli_test::RunShell;

// The building's mean radiance in an RGBA render: colours weighted by alpha (the sky and the sun
// disc, which a sunset view may hold, are left out).
double MeanBuilding(const fs::path& exr) {
  const Image image = ReadImage(exr.string(), /*keep_alpha=*/true);
  EXPECT_EQ(image.channels, 4) << exr;
  double sum = 0, weight = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      const double a = image.at(x, y, 3);
      for (int c = 0; c < 3; ++c) sum += a * image.at(x, y, c);
      weight += 3 * a;
    }
  EXPECT_GT(weight, 0) << exr << ": no building in view";
  return sum / weight;
}

double MeanRgb(const fs::path& file) {
  const Image image = ReadImage(file.string());
  double sum = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x)
      for (int c = 0; c < 3; ++c) sum += image.at(x, y, c);
  return sum / (3.0 * image.width * image.height);
}

class TimelapseCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(cli_test::TempDir("timelapse_cli"));
    testing::WriteExportTestScene(*dir_ / "scene");
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static fs::path Scene() { return *dir_ / "scene"; }
  // The times the library gives for the scene's site (Berkeley), 2026-06-21 at -08:00 (the
  // default from its longitude), sunrise to sunset every hour.
  static std::vector<UtcTime> ExpectedTimes() {
    TimelapseSchedule s;
    s.date = {2026, 6, 21};
    s.utc_offset_minutes = -480;
    s.step_s = 3600;
    return TimelapseTimesOf(Site{}, s).times;
  }
  static fs::path* dir_;
};
fs::path* TimelapseCli::dir_ = nullptr;

TEST_F(TimelapseCli, RendersTheDayAndDarkensTowardsSunset) {
  const fs::path out = *dir_ / "day";
  const Result r =
      RunRouen("timelapse " + Q(Scene()) + " --date 2026-06-21 --step 1h --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("local time UTC-08:00 (from the site's longitude"), std::string::npos)
      << r.out;
  const std::vector<UtcTime> times = ExpectedTimes();
  ASSERT_GE(times.size(), 12u);  // a midsummer day at 38 N: 14 hours of sun above 1 deg
  EXPECT_NE(r.out.find(std::to_string(times.size()) + " frames 160x120"), std::string::npos)
      << r.out;
  // Exactly one EXR and one PNG per time, named by it (and the MP4 when ffmpeg is installed).
  std::set<std::string> expected, found;
  for (UtcTime t : times) {
    expected.insert(SequenceFrameName(t) + ".exr");
    expected.insert(SequenceFrameName(t) + ".png");
  }
  const bool have_ffmpeg = !FindOnPath("ffmpeg").empty();
  if (have_ffmpeg) expected.insert("timelapse.mp4");
  for (const auto& e : fs::directory_iterator(out)) found.insert(e.path().filename().string());
  EXPECT_EQ(found, expected);
  // One exposure for the day: the building in the last frame (the sun 1-2 deg up) is darker than
  // at the highest sun, in radiance and in the PNGs.
  size_t top = 0;
  for (size_t i = 0; i < times.size(); ++i)
    if (ComputeSunPosition(times[i], Site{}).elevation_deg >
        ComputeSunPosition(times[top], Site{}).elevation_deg)
      top = i;
  const std::string noon = SequenceFrameName(times[top]), last = SequenceFrameName(times.back());
  EXPECT_LT(MeanBuilding(out / (last + ".exr")), MeanBuilding(out / (noon + ".exr")));
  EXPECT_LT(MeanRgb(out / (last + ".png")), MeanRgb(out / (noon + ".png")));
  if (!have_ffmpeg) GTEST_SKIP() << "ffmpeg is not installed (Debian: ffmpeg): no MP4 to check";
  const fs::path mp4 = out / "timelapse.mp4";
  EXPECT_NE(r.out.find(mp4.string() + ": H.264 MP4, " + std::to_string(times.size()) + " frames"),
            std::string::npos)
      << r.out;
  if (FindOnPath("ffprobe").empty()) GTEST_SKIP() << "ffprobe is not installed";
  const Result probe = RunShell(
      "ffprobe -v error -count_frames -select_streams v:0 -show_entries "
      "stream=nb_read_frames,codec_name,pix_fmt,width,height -of default=nw=1 " +
      Q(mp4));
  ASSERT_EQ(probe.code, 0) << probe.out;
  EXPECT_NE(probe.out.find("nb_read_frames=" + std::to_string(times.size()) + "\n"),
            std::string::npos)
      << probe.out;
  EXPECT_NE(probe.out.find("codec_name=h264"), std::string::npos) << probe.out;
  EXPECT_NE(probe.out.find("pix_fmt=yuv420p"), std::string::npos) << probe.out;
}

// Without ffmpeg on PATH the frames are written and the command says there is no video.
TEST_F(TimelapseCli, WithoutFfmpegKeepsTheFramesAndSaysSo) {
  const fs::path out = *dir_ / "no_ffmpeg";
  const Result r = RunShell("env PATH=/nonexistent " + std::string(ROUEN_BINARY) + " timelapse " +
                            Q(Scene()) + " --date 2026-06-21 --tz -07:00 --from 09:00 --to 11:00 " +
                            "--step 1h --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("no MP4: ffmpeg is not on PATH"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("local time UTC-07:00 (--tz)"), std::string::npos) << r.out;
  // 09:00, 10:00 and 11:00 PDT.
  for (const char* name : {"20260621T160000Z", "20260621T170000Z", "20260621T180000Z"}) {
    EXPECT_TRUE(fs::exists(out / (std::string(name) + ".exr"))) << name;
    EXPECT_TRUE(fs::exists(out / (std::string(name) + ".png"))) << name;
  }
  EXPECT_FALSE(fs::exists(out / "timelapse.mp4"));
}

TEST_F(TimelapseCli, RefusesBadInputsBeforeAnyWork) {
  const fs::path out = *dir_ / "refused";
  struct Case {
    std::string args, message;
  };
  for (const Case& c : std::vector<Case>{
           {"--date 2026-06-21 --from 03:00", "--from 03:00 is before sunrise"},
           {"--date 2026-06-21 --to 23:00", "--to 23:00 is after sunset"},
           {"--date 2026-02-30", "--date '2026-02-30': there is no such day"},
           {"--date 2026-06-21 --tz 8", "--tz '8'"},
           {"--date 2026-06-21 --from 7:00", "--from '7:00'"},
           {"--date 2026-06-21 --step 10parsecs", "--step '10parsecs'"},
           {"--date 2026-06-21 --view nope", "no view named 'nope'"},
           {"--date 2026-06-21 --look-at 0,0,0", "--look-at and --from-point go together"},
       }) {
    const Result r = RunRouen("timelapse " + Q(Scene()) + " " + c.args + " --out " + Q(out));
    EXPECT_EQ(r.code, 1) << c.args << "\n" << r.out;
    EXPECT_NE(r.out.find(c.message), std::string::npos) << c.args << "\n" << r.out;
    EXPECT_FALSE(fs::exists(out)) << c.args;
  }
  const Result missing =
      RunRouen("timelapse " + Q(*dir_ / "no-scene") + " --date 2026-06-21 --out " + Q(out));
  EXPECT_EQ(missing.code, 1) << missing.out;
  EXPECT_FALSE(fs::exists(out));
}

}  // namespace
}  // namespace rouen
