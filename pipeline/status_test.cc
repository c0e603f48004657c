#include "pipeline/status.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/mesh.h"
#include "core/solar.h"
#include "pipeline/capture_session.h"
#include "pipeline/scene.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

// A one-slot session written through SessionWriter: a sun bracket through an ND 4.5 filter
// (three exposures), a sky, a landscape and an architecture bracket (two exposures each),
// every frame with intrinsics and pose, and a building model.
void WriteSession(const fs::path& dir) {
  SessionInfo info;
  info.site = {37.8722, -122.2578, 60};
  info.rig = "sim.toml";
  info.model = "model.obj";
  info.extra["plan"] = nlohmann::json::object();  // as rouen capture records it
  info.capture_complete = true;
  SessionWriter w = SessionWriter::Create(dir, info);
  const Intrinsics k = Intrinsics::PinholeFov(4, 4, 60);
  const Image pixels(4, 4, 3, PixelUnits::kDigital, 100.f);
  const UtcTime t0 = ParseIso8601("2026-08-25T20:30:00Z");
  struct Bracket {
    Target target;
    std::vector<double> exposures;
    double nd;
  };
  const std::vector<Bracket> brackets = {{Target::kSun, {1e-3, 4e-3, 1.6e-2}, 4.5},
                                         {Target::kSky, {1e-3, 4e-3}, 0},
                                         {Target::kLandscape, {1e-3, 4e-3}, 0},
                                         {Target::kArchitecture, {1e-3, 4e-3}, 0}};
  int n = 0;
  for (const Bracket& b : brackets) {
    for (double e : b.exposures) {
      FrameRecord f;
      f.device = "cam0";
      f.target = b.target;
      f.group = std::string("slot0/") + TargetName(b.target) + "/view0";
      f.utc = t0.PlusSeconds(n++);
      f.exposure_s = e;
      f.nd_density = b.nd;
      f.intrinsics = k;
      f.pose = Pose{};
      w.Append(f, pixels);
    }
  }
  Mesh m;
  const int block = m.AddBlock("wall");
  m.AddPolygon({{0, 0, 0}, {10, 0, 0}, {10, 0, 10}, {0, 0, 10}}, block);
  WriteObj((dir / "model.obj").string(), m);
}

// The journal without the lines for which `drop` is true.
void DropJournalLines(const fs::path& dir, const std::function<bool(const FrameRecord&)>& drop) {
  const std::string text = ReadFileToString(dir / "frames.jsonl");
  std::string kept;
  size_t pos = 0;
  while (pos < text.size()) {
    const size_t end = text.find('\n', pos);
    const std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    if (!drop(ParseJournalLine(line))) kept += line + "\n";
  }
  WriteFileAtomic(dir / "frames.jsonl", kept);
}

// The journal with every line's record changed by `change`.
void RewriteJournal(const fs::path& dir, const std::function<void(FrameRecord&)>& change) {
  const std::string text = ReadFileToString(dir / "frames.jsonl");
  std::string out;
  size_t pos = 0;
  while (pos < text.size()) {
    const size_t end = text.find('\n', pos);
    FrameRecord f = ParseJournalLine(text.substr(pos, end - pos));
    pos = end + 1;
    change(f);
    out += nlohmann::json(f).dump() + "\n";
  }
  WriteFileAtomic(dir / "frames.jsonl", out);
}

std::vector<StatusProblemKind> Blocking(const SessionStatus& s) {
  std::vector<StatusProblemKind> out;
  for (const StatusProblem& p : s.problems)
    if (p.blocking) out.push_back(p.kind);
  return out;
}

const StatusProblem* Find(const SessionStatus& s, StatusProblemKind kind) {
  for (const StatusProblem& p : s.problems)
    if (p.kind == kind) return &p;
  return nullptr;
}

class StatusTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("rouen_status_test_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    dir_ = root_ / "s";
    WriteSession(dir_);
  }
  void TearDown() override { fs::remove_all(root_); }
  fs::path root_, dir_;
};

TEST_F(StatusTest, AWholeSessionIsSolvableAndDescribed) {
  const SessionStatus s = ReadSessionStatus(dir_);
  EXPECT_TRUE(s.Solvable());
  EXPECT_TRUE(s.problems.empty());
  EXPECT_TRUE(s.contents_verified);
  EXPECT_EQ(s.frames, 9);
  EXPECT_EQ(s.capture_complete, true);
  ASSERT_EQ(s.slots.size(), 1u);
  ASSERT_EQ(s.slots[0].brackets.size(), 4u);
  ASSERT_TRUE(s.slots[0].utc.has_value());
  EXPECT_TRUE(s.slots[0].utc_from_sky);
  // The sky frames were taken 3 and 4 s after the first: their median is the later one.
  EXPECT_EQ(*s.slots[0].utc, ParseIso8601("2026-08-25T20:30:04Z"));
  const auto& br = s.slots[0].brackets;
  const auto sun = std::find_if(br.begin(), br.end(),
                                [](const BracketStatus& b) { return b.target == Target::kSun; });
  ASSERT_NE(sun, br.end());
  EXPECT_EQ(sun->group, "slot0/sun/view0");
  EXPECT_EQ(sun->frames, 3);
  EXPECT_EQ(sun->hdr_frames, 0);
  EXPECT_DOUBLE_EQ(sun->min_exposure_s, 1e-3);
  EXPECT_DOUBLE_EQ(sun->max_exposure_s, 1.6e-2);
  EXPECT_EQ(sun->ldr_exposures, 3);
  EXPECT_DOUBLE_EQ(sun->max_nd_density, 4.5);
  EXPECT_EQ(sun->with_intrinsics, 3);
  EXPECT_EQ(sun->with_pose, 3);
  const nlohmann::json j = StatusToJson(s);
  EXPECT_EQ(j["solvable"], true);
  EXPECT_EQ(j["slots"][0]["brackets"].size(), 4u);
}

TEST_F(StatusTest, NoModelNamesSessionJsonAndWhatToSet) {
  SessionInfo info = ParseSessionInfo(ReadFileToString(dir_ / "session.json"), "session.json");
  info.model.clear();
  WriteFileAtomic(dir_ / "session.json", nlohmann::json(info).dump(2));
  const SessionStatus s = ReadSessionStatus(dir_);
  EXPECT_FALSE(s.Solvable());
  EXPECT_EQ(Blocking(s), std::vector<StatusProblemKind>{StatusProblemKind::kNoModel});
  const StatusProblem* p = Find(s, StatusProblemKind::kNoModel);
  ASSERT_NE(p, nullptr);
  EXPECT_NE(p->what.find((dir_ / "session.json").string()), std::string::npos) << p->what;
  EXPECT_NE(p->fix.find("\"model\""), std::string::npos) << p->fix;
}

TEST_F(StatusTest, ASlotWithoutItsSunBracketSaysWhichAndHowToCaptureIt) {
  DropJournalLines(dir_, [](const FrameRecord& f) { return f.target == Target::kSun; });
  const SessionStatus s = ReadSessionStatus(dir_);
  EXPECT_EQ(Blocking(s), std::vector<StatusProblemKind>{StatusProblemKind::kSlotLacksBracket});
  const StatusProblem* p = Find(s, StatusProblemKind::kSlotLacksBracket);
  ASSERT_NE(p, nullptr);
  EXPECT_NE(p->what.find("slot 0 lacks a sun bracket"), std::string::npos) << p->what;
  EXPECT_NE(
      p->fix.find("rouen capture --rig RIG --out " + dir_.string() + " --resume --target sun"),
      std::string::npos)
      << p->fix;
}

TEST_F(StatusTest, MissingAndChangedFramesAreNamed) {
  const Session before = Session::Load(dir_);
  fs::remove(dir_ / before.frames()[0].file);
  WriteFileAtomic(dir_ / before.frames()[1].file, "not the journalled bytes");
  const SessionStatus s = ReadSessionStatus(dir_);
  EXPECT_EQ(Blocking(s), (std::vector<StatusProblemKind>{StatusProblemKind::kMissingFile,
                                                         StatusProblemKind::kChecksum}));
  EXPECT_NE(Find(s, StatusProblemKind::kMissingFile)->what.find(before.frames()[0].file),
            std::string::npos);
  EXPECT_NE(Find(s, StatusProblemKind::kChecksum)->what.find(before.frames()[1].file),
            std::string::npos);
  // Without verification the changed file goes unseen; the missing one does not.
  StatusOptions fast;
  fast.verify_contents = false;
  const SessionStatus quick = ReadSessionStatus(dir_, fast);
  EXPECT_FALSE(quick.contents_verified);
  EXPECT_EQ(Blocking(quick), std::vector<StatusProblemKind>{StatusProblemKind::kMissingFile});
}

TEST_F(StatusTest, FramesWithoutPoseOrOneExposureOrBadValuesBlockTheSolve) {
  // Journal lines rewritten: the architecture bracket loses its poses, the landscape bracket
  // its second exposure (then no bracket can give the response curve), a sky frame gets a
  // negative gain.
  RewriteJournal(dir_, [](FrameRecord& f) {
    if (f.target == Target::kArchitecture) {
      f.pose.reset();
      f.exposure_s = 1e-3;
    }
    if (f.target == Target::kLandscape) f.exposure_s = 1e-3;
    if (f.target == Target::kSky && f.id == 5) f.gain = -1;
  });
  const SessionStatus s = ReadSessionStatus(dir_);
  EXPECT_FALSE(s.Solvable());
  ASSERT_NE(Find(s, StatusProblemKind::kNoGeometry), nullptr);
  EXPECT_NE(Find(s, StatusProblemKind::kNoGeometry)->what.find("slot0/architecture/view0"),
            std::string::npos);
  EXPECT_NE(Find(s, StatusProblemKind::kNoGeometry)->fix.find("rouen calib pose"),
            std::string::npos);
  EXPECT_NE(Find(s, StatusProblemKind::kNoResponse), nullptr);
  ASSERT_NE(Find(s, StatusProblemKind::kFrameValue), nullptr);
  EXPECT_NE(Find(s, StatusProblemKind::kFrameValue)->what.find("gain -1 is not positive"),
            std::string::npos);
}

// What the solve refuses before any work, status reports: session.json's solve options, a sky
// mask file outside the session, missing or not the sky photo's size, and a frame whose image
// is not the size its intrinsics give.
TEST_F(StatusTest, WhatTheSolveRefusesAtOnceBlocksItHere) {
  SessionInfo info = ParseSessionInfo(ReadFileToString(dir_ / "session.json"), "session.json");
  info.solve_config = {{"grid", {{"spacing_m", -3}}}};
  WriteFileAtomic(dir_ / "session.json", nlohmann::json(info).dump(2));
  SessionStatus s = ReadSessionStatus(dir_);
  EXPECT_EQ(Blocking(s), std::vector<StatusProblemKind>{StatusProblemKind::kSolveConfig});
  EXPECT_NE(Find(s, StatusProblemKind::kSolveConfig)->what.find("grid.spacing_m"),
            std::string::npos)
      << Find(s, StatusProblemKind::kSolveConfig)->what;

  info.solve_config = nlohmann::json::object();
  for (const std::string& file : {std::string("../mask.png"), std::string("nosuch.png")}) {
    SkyMaskSpec mask;
    mask.file = file;
    info.sky_masks = {{"*", mask}};
    WriteFileAtomic(dir_ / "session.json", nlohmann::json(info).dump(2));
    s = ReadSessionStatus(dir_);
    EXPECT_EQ(Blocking(s), std::vector<StatusProblemKind>{StatusProblemKind::kSkyMask}) << file;
  }
  WriteImage((dir_ / "mask.png").string(), Image(5, 4, 1, PixelUnits::kDigital, 255.f),
             StoredType::kUint8);
  SkyMaskSpec mask;
  mask.file = "mask.png";
  info.sky_masks = {{"*", mask}};
  WriteFileAtomic(dir_ / "session.json", nlohmann::json(info).dump(2));
  s = ReadSessionStatus(dir_);
  ASSERT_EQ(Blocking(s), std::vector<StatusProblemKind>{StatusProblemKind::kSkyMask});
  EXPECT_NE(Find(s, StatusProblemKind::kSkyMask)->what.find("mask.png"), std::string::npos);
  WriteImage((dir_ / "mask.png").string(), Image(4, 4, 1, PixelUnits::kDigital, 255.f),
             StoredType::kUint8);
  EXPECT_TRUE(ReadSessionStatus(dir_).Solvable());

  // A frame's intrinsics claim another size than its image's.
  RewriteJournal(dir_, [](FrameRecord& f) {
    if (f.id == 1) f.intrinsics->width = 5;
  });
  s = ReadSessionStatus(dir_);
  ASSERT_EQ(Blocking(s), std::vector<StatusProblemKind>{StatusProblemKind::kFrameImage});
  EXPECT_NE(Find(s, StatusProblemKind::kFrameImage)->what.find("is 4x4 but its intrinsics are 5x4"),
            std::string::npos)
      << Find(s, StatusProblemKind::kFrameImage)->what;
}

// Photos timed twelve hours off (a camera clock in the wrong time zone) put the slot at night:
// status names the slot, its time and the sun's depth with the fix, and the solve refuses it
// before any work with the same words (it used to fail later, on the sun "outside the camera's
// field of view").
TEST_F(StatusTest, ASlotAtNightIsNamedByStatusAndRefusedBySolve) {
  RewriteJournal(dir_, [](FrameRecord& f) { f.utc = f.utc.PlusSeconds(12 * 3600); });
  const SessionStatus s = ReadSessionStatus(dir_);
  ASSERT_EQ(Blocking(s), std::vector<StatusProblemKind>{StatusProblemKind::kNight});
  const StatusProblem* p = Find(s, StatusProblemKind::kNight);
  // The sky frames' median time: 08:30:04 UTC, 01:30 in Berkeley, the sun 42 deg down.
  EXPECT_NE(p->what.find("slot 0 (2026-08-26T08:30:04Z): the sun is"), std::string::npos)
      << p->what;
  const SunPosition sun = ComputeSunPosition(*s.slots[0].utc, s.info.site);
  ASSERT_LT(sun.elevation_deg, -30);
  char depth[32];
  std::snprintf(depth, sizeof depth, "%.1f deg below the horizon", -sun.elevation_deg);
  EXPECT_NE(p->what.find(depth), std::string::npos) << p->what;
  EXPECT_NE(p->fix.find("capture the slot again in daylight"), std::string::npos) << p->fix;
  SolveFolderRequest request;
  request.session = dir_;
  request.out = root_ / "scene";
  std::string solve_error;
  try {
    SolveSessionFolder(request);
  } catch (const Error& e) {
    solve_error = e.what();
  }
  EXPECT_EQ(solve_error, p->what);
  EXPECT_FALSE(fs::exists(root_ / "scene"));
  // Twelve hours back: day again.
  RewriteJournal(dir_, [](FrameRecord& f) { f.utc = f.utc.PlusSeconds(-12 * 3600); });
  EXPECT_TRUE(ReadSessionStatus(dir_).Solvable());
}

TEST_F(StatusTest, AnUnfinishedCaptureIsANoteNotABlock) {
  SessionInfo info = ParseSessionInfo(ReadFileToString(dir_ / "session.json"), "session.json");
  info.capture_complete = false;
  WriteFileAtomic(dir_ / "session.json", nlohmann::json(info).dump(2));
  const SessionStatus s = ReadSessionStatus(dir_);
  EXPECT_TRUE(s.Solvable());
  ASSERT_EQ(s.problems.size(), 1u);
  EXPECT_EQ(s.problems[0].kind, StatusProblemKind::kCaptureUnfinished);
  EXPECT_NE(s.problems[0].fix.find("--resume"), std::string::npos);
}

TEST_F(StatusTest, NotASessionIsAnError) {
  EXPECT_THROW(ReadSessionStatus(root_ / "nothing"), Error);
  fs::create_directories(root_ / "empty");
  EXPECT_THROW(ReadSessionStatus(root_ / "empty"), Error);
}

}  // namespace
}  // namespace rouen
