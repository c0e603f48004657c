#include "pipeline/timelapse.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "core/error_of.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

const Site kBerkeley{37.8722, -122.2578, 60};

double Elevation(UtcTime t, const Site& site = kBerkeley) {
  return ComputeSunPosition(t, site).elevation_deg;
}

TEST(Timelapse, FramesAreNamedByTheirUtcTime) {
  EXPECT_EQ(SequenceFrameName(ParseIso8601("2026-08-25T19:40:00Z")), "20260825T194000Z");
}

TEST(Timelapse, ParsesClockTimes) {
  EXPECT_EQ(ParseClockSeconds("07:30", "--from"), 7 * 3600 + 30 * 60);
  EXPECT_EQ(ParseClockSeconds("00:00", "--from"), 0);
  EXPECT_EQ(ParseClockSeconds("23:59:59", "--to"), 86399);
  for (const char* bad : {"7:30", "24:00", "07:60", "07:30:60", "noon", "07:30:", "", "07-30"}) {
    const std::string e = ErrorOf([&] { ParseClockSeconds(bad, "--from"); });
    EXPECT_NE(e.find("--from '" + std::string(bad) + "'"), std::string::npos) << bad << ": " << e;
  }
}

TEST(Timelapse, ParsesDatesAndOffsets) {
  const LocalDate d = ParseLocalDate("2026-08-25", "--date");
  EXPECT_EQ(d.year, 2026);
  EXPECT_EQ(d.month, 8);
  EXPECT_EQ(d.day, 25);
  EXPECT_EQ(ParseLocalDate("2028-02-29", "--date").day, 29);
  for (const char* bad : {"2026-02-29", "2026-13-01", "2026-8-25", "25/08/2026", "2026-08-25T"})
    EXPECT_NE(ErrorOf([&] { ParseLocalDate(bad, "--date"); }).find("--date"), std::string::npos)
        << bad;
  EXPECT_EQ(ParseUtcOffsetMinutes("-07:00", "--tz"), -420);
  EXPECT_EQ(ParseUtcOffsetMinutes("+05:30", "--tz"), 330);
  EXPECT_EQ(ParseUtcOffsetMinutes("Z", "--tz"), 0);
  for (const char* bad : {"07:00", "+15:00", "-07", "+7:00", "", "-07:75"})
    EXPECT_NE(ErrorOf([&] { ParseUtcOffsetMinutes(bad, "--tz"); }).find("--tz"), std::string::npos)
        << bad;
  EXPECT_EQ(FormatUtcOffset(-420), "-07:00");
  EXPECT_EQ(FormatUtcOffset(330), "+05:30");
  // Berkeley, 122.26 deg west: 8.15 hours, rounded to -08:00.
  EXPECT_EQ(LongitudeUtcOffsetMinutes(kBerkeley), -480);
  EXPECT_EQ(LongitudeUtcOffsetMinutes(Site{48.86, 2.35, 35}), 0);
}

// Sunrise and sunset are the crossings of the threshold, to the second.
TEST(Timelapse, SunriseAndSunsetCrossTheThreshold) {
  const Daylight d = DaylightOf(kBerkeley, {2026, 8, 25}, -420, 1.0);
  EXPECT_FALSE(d.up_at_midnight);
  EXPECT_GE(Elevation(d.sunrise), 1.0);
  EXPECT_LT(Elevation(d.sunrise.PlusSeconds(-1)), 1.0);
  EXPECT_GE(Elevation(d.sunset), 1.0);
  EXPECT_LT(Elevation(d.sunset.PlusSeconds(1)), 1.0);
  // A late-August day at 38 N: sunrise near 06:40 PDT, sunset near 19:45, the sun near 62 deg
  // at about 13:15 (the equation of time and 2 deg west of the zone's meridian).
  EXPECT_EQ(FormatLocalClock(d.sunrise, -420).substr(0, 2), "06");
  EXPECT_EQ(FormatLocalClock(d.sunset, -420).substr(0, 2), "19");
  EXPECT_NEAR(d.highest_elevation_deg, 62, 1.5);
}

TEST(Timelapse, SunriseToSunsetFramesAreTheDaylightOnTheStepGrid) {
  TimelapseSchedule s;
  s.date = {2026, 8, 25};
  s.utc_offset_minutes = -420;
  s.step_s = 600;
  const TimelapseTimes r = TimelapseTimesOf(kBerkeley, s);
  ASSERT_GT(r.times.size(), 60u);  // about 13 hours at 10 min
  const UtcTime first = r.times.front(), last = r.times.back();
  // The first frame's sun is at or above the threshold, the frame a step before it below.
  EXPECT_GE(Elevation(first), s.min_elevation_deg);
  EXPECT_LT(Elevation(first.PlusSeconds(-s.step_s)), s.min_elevation_deg);
  EXPECT_GE(Elevation(last), s.min_elevation_deg);
  EXPECT_LT(Elevation(last.PlusSeconds(s.step_s)), s.min_elevation_deg);
  for (size_t i = 1; i < r.times.size(); ++i)
    EXPECT_EQ(r.times[i].UnixSeconds() - r.times[i - 1].UnixSeconds(), 600);
  // On the grid from local midnight: whole ten minutes of local time.
  const std::string clock = FormatLocalClock(first, -420);
  EXPECT_EQ(clock.substr(4), "0:00") << clock;
}

TEST(Timelapse, ClockTimesGiveTheirGrid) {
  TimelapseSchedule s;
  s.date = {2026, 8, 25};
  s.utc_offset_minutes = -420;
  s.from = "08:05";
  s.to = "12:00";
  s.step_s = 3600;
  const TimelapseTimes r = TimelapseTimesOf(kBerkeley, s);
  ASSERT_EQ(r.times.size(), 4u);  // 08:05, 09:05, 10:05, 11:05
  EXPECT_EQ(r.times.front().Iso8601(0), "2026-08-25T15:05:00Z");
  EXPECT_EQ(r.times.back().Iso8601(0), "2026-08-25T18:05:00Z");
  s.to = "sunset";
  const TimelapseTimes to_sunset = TimelapseTimesOf(kBerkeley, s);
  EXPECT_LT(Elevation(to_sunset.times.back().PlusSeconds(3600)), s.min_elevation_deg);
  EXPECT_EQ(FormatLocalClock(to_sunset.times.back(), -420).substr(2), ":05:00");
}

TEST(Timelapse, RefusesTimesOutsideDaylightAndEmptySpans) {
  TimelapseSchedule s;
  s.date = {2026, 8, 25};
  s.utc_offset_minutes = -420;
  s.from = "04:00";
  EXPECT_NE(ErrorOf([&] { TimelapseTimesOf(kBerkeley, s); }).find("--from 04:00 is before sunrise"),
            std::string::npos);
  s.from = "sunrise";
  s.to = "22:00";
  EXPECT_NE(ErrorOf([&] { TimelapseTimesOf(kBerkeley, s); }).find("--to 22:00 is after sunset"),
            std::string::npos);
  s.from = "12:00";
  s.to = "10:00";
  EXPECT_NE(ErrorOf([&] { TimelapseTimesOf(kBerkeley, s); }).find("is not after --from"),
            std::string::npos);
  s.from = "12:00";
  s.to = "12:05";
  s.step_s = 600;
  EXPECT_EQ(TimelapseTimesOf(kBerkeley, s).times.size(), 1u);  // 12:00 itself
  s.to = "12:00:30";
  s.from = "12:00:10";
  s.step_s = 60;
  EXPECT_EQ(TimelapseTimesOf(kBerkeley, s).times.size(), 1u);
  s.from = "sunrise";
  s.to = "sunset";
  s.step_s = 1;
  s.max_frames = 5000;
  EXPECT_NE(ErrorOf([&] { TimelapseTimesOf(kBerkeley, s); }).find("take a longer --step"),
            std::string::npos);
  s.step_s = 1e-300;  // more frames than any integer counts: counted in floating point
  EXPECT_NE(ErrorOf([&] { TimelapseTimesOf(kBerkeley, s); }).find("e+304 frames, more than 5000"),
            std::string::npos);
  s.step_s = 0;
  EXPECT_NE(ErrorOf([&] { TimelapseTimesOf(kBerkeley, s); }).find("--step"), std::string::npos);
}

TEST(Timelapse, PolarNightIsRefusedAndPolarDayFillsTheDay) {
  const Site north{80, 15, 0};
  const std::string e = ErrorOf([&] { DaylightOf(north, {2026, 12, 21}, 60); });
  EXPECT_NE(e.find("stays below 1 deg"), std::string::npos) << e;
  const Daylight d = DaylightOf(north, {2026, 6, 21}, 60);
  EXPECT_TRUE(d.up_at_midnight);
  EXPECT_EQ(d.sunrise, d.midnight);
  EXPECT_EQ(d.sunset, d.midnight.PlusSeconds(86400));
}

TEST(Timelapse, Mp4WithoutFfmpegSaysSoAndWritesNothing) {
  const fs::path dir = fs::temp_directory_path() / ("rouen_mp4_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  Mp4Options o;
  o.ffmpeg = (dir / "no-ffmpeg").string();
  const std::string e = ErrorOf([&] { EncodeMp4({(dir / "a.png").string()}, dir / "t.mp4", o); });
  EXPECT_NE(e.find("is not on PATH"), std::string::npos) << e;
  EXPECT_FALSE(fs::exists(dir / "t.mp4"));
  o.fps = 0;
  EXPECT_NE(ErrorOf([&] { o.Validate(); }).find("--fps"), std::string::npos);
  fs::remove_all(dir);
}

// ffmpeg run through RunProcess: its failure names the exit code and its last messages, and
// no video is left behind.
TEST(Timelapse, Mp4WhenFfmpegFailsNamesItsExitAndMessages) {
  const fs::path dir = fs::temp_directory_path() / ("rouen_mp4_fail_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const fs::path fake = dir / "ffmpeg";
  std::ofstream(fake) << "#!/bin/sh\necho 'bad input frame' >&2\nexit 3\n";
  fs::permissions(fake, fs::perms::owner_all);
  Mp4Options o;
  o.ffmpeg = fake.string();
  const std::string e = ErrorOf([&] { EncodeMp4({(dir / "a.png").string()}, dir / "t.mp4", o); });
  EXPECT_NE(e.find("ffmpeg failed (exit 3)"), std::string::npos) << e;
  EXPECT_NE(e.find("bad input frame"), std::string::npos) << e;
  EXPECT_NE(e.find("the frames are kept"), std::string::npos) << e;
  EXPECT_FALSE(fs::exists(dir / "t.mp4"));
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
