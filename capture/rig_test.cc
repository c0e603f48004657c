#include "capture/rig.h"

#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "core/error.h"

namespace rouen {
namespace {

const char* kGood = R"(
[rig]
name = "t"
kind = "sim"
[site]
lat_deg = 10.5
lon_deg = 20.25
height_m = 3
[bracket]
step_stops = 1.5
[plan]
date = "2026-08-25"
timezone = "-07:00"
times = ["07:45", "16:00"]
heldout = "16:00"
aureole_exposures_s = [0.001, 0.002]
)";

TEST(RigTest, ParsesSiteBracketAndSlots) {
  RigConfig r = ParseRig(kGood, "good.toml");
  EXPECT_EQ(r.kind, "sim");
  EXPECT_DOUBLE_EQ(r.site.lat_deg, 10.5);
  EXPECT_DOUBLE_EQ(r.site.lon_deg, 20.25);
  EXPECT_DOUBLE_EQ(r.plan.bracket.step_stops, 1.5);
  ASSERT_EQ(r.plan.slots.size(), 2u);
  // 07:45 at -07:00 is 14:45 UTC.
  EXPECT_EQ(r.plan.slots[0].Iso8601(0), "2026-08-25T14:45:00Z");
  EXPECT_EQ(r.heldout_slot, 1);
  ASSERT_EQ(r.plan.aureole_exposures_s.size(), 2u);
}

void ExpectErrorAt(const std::string& text, const std::string& where) {
  try {
    ParseRig(text, "bad.toml");
    FAIL() << "no error for:\n" << text;
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(where), std::string::npos) << e.what();
  }
}

TEST(RigTest, MalformedRigsNameFileAndLine) {
  ExpectErrorAt("[rig]\nname = \"x\"\nkind = = \"sim\"\n", "bad.toml:3");         // syntax
  ExpectErrorAt("[rig]\nname = \"x\"\nkind = \"webcam9\"\n", "bad.toml:3");       // unknown kind
  ExpectErrorAt(std::string(kGood) + "\n[camera]\ncontrol_latency_frames = \"two\"\n",
                "bad.toml:");                                                     // type
  std::string bad_time = kGood;
  bad_time.replace(bad_time.find("07:45"), 5, "25:99");
  ExpectErrorAt(bad_time, "bad slot time");
  std::string bad_held = kGood;
  bad_held.replace(bad_held.find("heldout = \"16:00\""), 17, "heldout = \"12:00\"");
  ExpectErrorAt(bad_held, "heldout time '12:00'");
  std::string bad_step = kGood;
  bad_step.replace(bad_step.find("1.5"), 3, "9.0");
  ExpectErrorAt(bad_step, "step_stops");
  ExpectErrorAt("[site]\nlat_deg = 1\n", "missing table [rig]");
}

TEST(RigTest, ShippedRigsLoad) {
  for (const char* name : {"sim.toml", "replay.toml"}) {
    std::filesystem::path p = std::filesystem::path(ROUEN_SOURCE_DIR) / "rigs" / name;
    RigConfig r = LoadRig(p);
    EXPECT_FALSE(r.name.empty()) << p;
  }
  RigConfig sim = LoadRig(std::filesystem::path(ROUEN_SOURCE_DIR) / "rigs/sim.toml");
  EXPECT_EQ(sim.plan.slots.size(), 5u);
  EXPECT_GE(sim.heldout_slot, 0);
}

TEST(RigTest, MissingFileIsAnError) {
  EXPECT_THROW(LoadRig("/nonexistent/rig.toml"), Error);
}

}  // namespace
}  // namespace rouen
