#include "core/session.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <string>

#include "core/error.h"
#include "core/fault_io.h"
#include "core/files.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace rouen {
namespace {

class SessionTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() / ("rouen_core_session_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    fs::create_directories(root_);
    dir_ = root_ / "s1";
  }
  void TearDown() override { fs::remove_all(root_); }

  static SessionInfo Info() {
    SessionInfo info;
    info.site = Site{48.4431, 1.0892, 140.5};
    info.site_source = "gps";
    info.rig = "rigs/field.toml";
    info.created_utc = "2024-06-21T05:00:00.000Z";
    info.clock_offset_s = -0.25;
    info.model = "model/cathedral.obj";
    info.notes = "west front";
    info.extra = json{{"operator", "cm"}};
    return info;
  }
  static FrameRecord Meta(Target target, bool hdr, double exposure) {
    FrameRecord f;
    f.device = "sim0";
    f.target = target;
    f.group = BracketName(1, target, 1);
    f.slot = 1;
    f.utc = ParseIso8601("2024-06-21T09:15:00.123456789Z");
    f.hdr = hdr;
    f.exposure_s = exposure;
    f.gain = 2.0;
    f.aperture_f = 8.0;
    f.nd_density = hdr ? 0.0 : 3.0;
    f.sun_azimuth_deg = 101.5;
    f.sun_elevation_deg = 38.25;
    return f;
  }
  static Image Pixels(bool hdr, float scale) {
    Image img(6, 4, 3, hdr ? PixelUnits::kRadiance : PixelUnits::kDigital);
    for (size_t i = 0; i < img.data.size(); ++i) {
      img.data[i] = hdr ? scale * (1 + i) : static_cast<float>((i * 11) % 256);
    }
    return img;
  }
  // Writes three frames: LDR with gps/pose/intrinsics, HDR in half range, HDR beyond it.
  void WriteThree() {
    SessionWriter w = SessionWriter::Create(dir_, Info());
    FrameRecord a = Meta(Target::kArchitecture, false, 1.0 / 250);
    GpsFix fix;
    fix.utc = ParseIso8601("2024-06-21T09:14:59.5Z");
    fix.lat_deg = 48.44312;
    fix.lon_deg = 1.08921;
    fix.height_m = 141.2;
    fix.mode = 3;
    fix.satellites = 9;
    fix.hdop = 0.8;
    a.gps = fix;
    a.intrinsics = Intrinsics::PinholeFov(6, 4, 60);
    a.intrinsics->k1 = -0.1;
    a.pose = Pose::Level(Eigen::Vector3d(1, 2, 1.6), 80, 10);
    w.Append(a, Pixels(false, 1));
    w.Append(Meta(Target::kSky, true, 0), Pixels(true, 0.5f));
    w.Append(Meta(Target::kSun, true, 0), Pixels(true, 1e5f));
  }
  std::string Journal() const { return ReadFileToString(dir_ / "frames.jsonl"); }
  void SetJournal(const std::string& s) const { WriteFileAtomic(dir_ / "frames.jsonl", s); }
  std::vector<std::string> Lines() const {
    std::vector<std::string> out;
    const std::string j = Journal();
    size_t pos = 0;
    while (pos < j.size()) {
      const size_t nl = j.find('\n', pos);
      out.push_back(j.substr(pos, nl - pos));
      pos = nl + 1;
    }
    return out;
  }
  void ExpectLoadError(const std::string& phrase) const {
    try {
      Session::Load(dir_);
      ADD_FAILURE() << "loaded; wanted " << phrase;
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(phrase), std::string::npos) << e.what();
    }
  }

  fs::path root_, dir_;
};

TEST_F(SessionTest, RoundTrip) {
  WriteThree();
  EXPECT_TRUE(fs::exists(dir_ / "frames" / "000001.png"));
  EXPECT_TRUE(fs::exists(dir_ / "frames" / "000002.exr"));
  EXPECT_TRUE(fs::exists(dir_ / "frames" / "000003.exr"));
  const Session s = Session::Load(dir_);
  EXPECT_TRUE(s.warnings().empty());
  const SessionInfo& info = s.info();
  EXPECT_EQ(info.site.lat_deg, 48.4431);
  EXPECT_EQ(info.site.height_m, 140.5);
  EXPECT_EQ(info.site_source, "gps");
  EXPECT_EQ(info.rig, "rigs/field.toml");
  EXPECT_EQ(info.clock_offset_s, -0.25);
  EXPECT_EQ(info.model, "model/cathedral.obj");
  EXPECT_EQ(info.notes, "west front");
  EXPECT_EQ(info.extra["operator"], "cm");
  ASSERT_EQ(s.frames().size(), 3u);
  const FrameRecord& a = s.frames()[0];
  EXPECT_EQ(a.id, 1);
  EXPECT_EQ(a.file, "frames/000001.png");
  EXPECT_EQ(a.target, Target::kArchitecture);
  EXPECT_EQ(a.group, "slot1/architecture/view1");
  EXPECT_EQ(a.slot, 1);
  EXPECT_EQ(a.utc, ParseIso8601("2024-06-21T09:15:00.123456789Z"));
  EXPECT_EQ(a.exposure_s, 1.0 / 250);
  EXPECT_EQ(a.gain, 2.0);
  EXPECT_EQ(a.aperture_f, 8.0);
  EXPECT_EQ(a.nd_density, 3.0);
  EXPECT_EQ(a.sun_azimuth_deg, 101.5);
  ASSERT_TRUE(a.gps.has_value());
  EXPECT_EQ(a.gps->utc, ParseIso8601("2024-06-21T09:14:59.5Z"));
  EXPECT_EQ(a.gps->satellites, 9);
  EXPECT_EQ(a.gps->lat_deg, 48.44312);
  EXPECT_TRUE(a.gps->valid());
  ASSERT_TRUE(a.intrinsics.has_value());
  EXPECT_EQ(a.intrinsics->k1, -0.1);
  ASSERT_TRUE(a.pose.has_value());
  EXPECT_EQ(a.pose->rotation, Pose::Level(Eigen::Vector3d(1, 2, 1.6), 80, 10).rotation);
  EXPECT_EQ(a.sha256, Sha256File(dir_ / a.file));
  EXPECT_FALSE(s.frames()[1].gps.has_value());
  EXPECT_FALSE(s.frames()[1].pose.has_value());
  EXPECT_TRUE(s.frames()[1].hdr);
  EXPECT_EQ(s.frames()[2].target, Target::kSun);

  // Pixels: LDR exactly, HDR within half precision, beyond-half HDR stored as float.
  const Image ldr = s.LoadFrame(a);
  EXPECT_EQ(ldr.units, PixelUnits::kDigital);
  EXPECT_EQ(ldr.data, Pixels(false, 1).data);
  const Image sky = s.LoadFrame(s.frames()[1]);
  EXPECT_EQ(sky.units, PixelUnits::kRadiance);
  const Image want = Pixels(true, 0.5f);
  for (size_t i = 0; i < want.data.size(); ++i) {
    EXPECT_NEAR(sky.data[i], want.data[i], want.data[i] / 2048);
  }
  EXPECT_EQ(s.LoadFrame(s.frames()[2]).data, Pixels(true, 1e5f).data);

  // The journal: one compact object per line with the documented keys.
  const auto lines = Lines();
  ASSERT_EQ(lines.size(), 3u);
  const json j = json::parse(lines[0]);
  for (const char* key :
       {"id", "device", "target", "group", "slot", "utc", "hdr", "exposure_s", "gain", "aperture_f",
        "nd_density", "gps", "sun", "intrinsics", "pose", "file", "sha256"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["utc"], "2024-06-21T09:15:00.123456789Z");
  EXPECT_EQ(j["target"], "architecture");
  EXPECT_TRUE(json::parse(lines[1])["gps"].is_null());
  const json info_json = json::parse(ReadFileToString(dir_ / "session.json"));
  for (const char* key : {"format_version", "site", "site_source", "rig", "created_utc",
                          "clock_offset_s", "model", "notes", "extra"}) {
    EXPECT_TRUE(info_json.contains(key)) << key;
  }
}

// An HDR frame whose largest value would round to the half-float maximum (65499.5 -> 65504,
// where a half frame clips and the sun's measurement refuses the disc) keeps full precision.
TEST_F(SessionTest, HdrNearTheHalfMaximumIsNotRoundedToIt) {
  SessionWriter w = SessionWriter::Create(dir_, Info());
  Image near = Pixels(true, 1);
  near.data[5] = 65499.5f;
  w.Append(Meta(Target::kSun, true, 0), near);
  Image below = Pixels(true, 1);
  below.data[5] = 65400.f;  // a half value's neighbourhood, far from the maximum: half
  w.Append(Meta(Target::kSun, true, 0), below);
  const Session s = Session::Load(dir_);
  EXPECT_EQ(s.LoadFrame(s.frames()[0]).data[5], 65499.5f);
  const float back = s.LoadFrame(s.frames()[1]).data[5];
  EXPECT_NEAR(back, 65400.f, 32.f);
  EXPECT_LT(back, 65504.f);
}

TEST_F(SessionTest, ResumeContinuesIdsAndCleansUp) {
  WriteThree();
  WriteFileAtomic(dir_ / "frames" / "000004.png.tmp-99-0.png", "partial");
  {
    SessionWriter w = SessionWriter::Resume(dir_);
    EXPECT_EQ(w.frames().size(), 3u);
    EXPECT_EQ(w.info().notes, "west front");
    const FrameRecord r = w.Append(Meta(Target::kLandscape, false, 0.01), Pixels(false, 1));
    EXPECT_EQ(r.id, 4);
    EXPECT_EQ(r.file, "frames/000004.png");
    SessionInfo info = w.info();
    info.site_source = "rig";
    w.UpdateInfo(info);
  }
  EXPECT_FALSE(fs::exists(dir_ / "frames" / "000004.png.tmp-99-0.png"));
  const Session s = Session::Load(dir_);
  ASSERT_EQ(s.frames().size(), 4u);
  EXPECT_EQ(s.frames()[3].id, 4);
  EXPECT_EQ(s.frames()[3].target, Target::kLandscape);
  EXPECT_EQ(s.info().site_source, "rig");
}

TEST_F(SessionTest, TruncatedLastLineIsToleratedAndRepaired) {
  WriteThree();
  const std::string full = Journal();
  const std::string cut = full.substr(0, full.size() - 40);  // crash mid-line 3
  SetJournal(cut);
  const Session s = Session::Load(dir_);
  EXPECT_EQ(s.frames().size(), 2u);
  ASSERT_EQ(s.warnings().size(), 1u);
  EXPECT_NE(s.warnings()[0].find("frames.jsonl:3"), std::string::npos) << s.warnings()[0];
  SessionWriter w = SessionWriter::Resume(dir_);
  EXPECT_EQ(w.frames().size(), 2u);
  // The partial line was cut away and the id of the lost frame is used again.
  EXPECT_EQ(Journal(), full.substr(0, full.rfind('\n', full.size() - 2) + 1));
  EXPECT_EQ(w.Append(Meta(Target::kSky, false, 0.1), Pixels(false, 1)).id, 3);
  EXPECT_EQ(Session::Load(dir_).frames().size(), 3u);
  EXPECT_TRUE(Session::Load(dir_).warnings().empty());
}

TEST_F(SessionTest, LastLineMissingOnlyItsNewlineIsKept) {
  WriteThree();
  const std::string full = Journal();
  SetJournal(full.substr(0, full.size() - 1));
  EXPECT_EQ(Session::Load(dir_).frames().size(), 3u);
  SessionWriter w = SessionWriter::Resume(dir_);
  EXPECT_EQ(Journal(), full);
  EXPECT_EQ(w.Append(Meta(Target::kSky, false, 0.1), Pixels(false, 1)).id, 4);
}

TEST_F(SessionTest, MalformedMiddleLineIsAnErrorWithItsLine) {
  WriteThree();
  auto lines = Lines();
  SetJournal(lines[0] + "\n{\"id\": 2, \"device\": \n" + lines[2] + "\n");
  ExpectLoadError("frames.jsonl:2:");
  // A missing key is named.
  json j = json::parse(lines[1]);
  j.erase("exposure_s");
  SetJournal(lines[0] + "\n" + j.dump() + "\n" + lines[2] + "\n");
  ExpectLoadError("frames.jsonl:2: frame record: missing key \"exposure_s\"");
  j = json::parse(lines[1]);
  j["target"] = "moon";
  SetJournal(lines[0] + "\n" + j.dump() + "\n");
  ExpectLoadError("moon");
  j = json::parse(lines[1]);
  j["utc"] = "2024-06-21T09:15:00";  // no zone
  SetJournal(j.dump() + "\n");
  ExpectLoadError("frames.jsonl:1:");
  SetJournal(lines[0] + "\n" + lines[0] + "\n");
  ExpectLoadError("duplicate");
}

TEST_F(SessionTest, PathsLeavingTheFolderAreRefused) {
  WriteThree();
  auto lines = Lines();
  fs::copy_file(dir_ / "frames" / "000001.png", root_ / "x.png");
  for (const char* bad : {"../x.png", "/etc/passwd", "frames/../../x.png"}) {
    json j = json::parse(lines[0]);
    j["file"] = bad;
    SetJournal(j.dump() + "\n" + lines[1] + "\n");
    ExpectLoadError("frames.jsonl:1:");
    ExpectLoadError(bad);
  }
  const Session s = [&] {
    SetJournal(lines[0] + "\n");
    return Session::Load(dir_);
  }();
  FrameRecord f = s.frames()[0];
  f.file = "../x.png";
  EXPECT_THROW(s.PathOf(f), Error);
  EXPECT_THROW(s.LoadFrame(f), Error);
}

TEST_F(SessionTest, MissingFileAndShaMismatch) {
  WriteThree();
  {
    const Session s = Session::Load(dir_);
    // Flip the pixels of frame 1 behind the journal's back.
    Image other = Pixels(false, 1);
    other.data[0] = 200;
    WriteImage((dir_ / "frames" / "000001.png").string(), other, StoredType::kUint8);
    try {
      s.LoadFrame(s.frames()[0]);
      ADD_FAILURE();
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("sha256"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("000001.png"), std::string::npos) << e.what();
    }
  }
  fs::remove(dir_ / "frames" / "000002.exr");
  ExpectLoadError("frames.jsonl:2:");
  ExpectLoadError("missing");
}

TEST_F(SessionTest, CreateRefusesNonEmptyFolder) {
  fs::create_directories(dir_);
  WriteFileAtomic(dir_ / "something.txt", "x");
  try {
    SessionWriter::Create(dir_, Info());
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(dir_.string()), std::string::npos);
  }
  // An existing empty folder is fine, and a second Create on it is refused.
  const fs::path empty = root_ / "empty";
  fs::create_directories(empty);
  { SessionWriter w = SessionWriter::Create(empty, Info()); }
  EXPECT_THROW(SessionWriter::Create(empty, Info()), Error);
  EXPECT_TRUE(Session::Load(empty).frames().empty());
}

TEST_F(SessionTest, PngCompressionLevelChangesTheFileNotThePixels) {
  // A noisy 64x48 frame (hash noise: what a sensor gives), stored at zlib levels 1, 6 and 9.
  Image noisy(64, 48, 3, PixelUnits::kDigital);
  for (size_t i = 0; i < noisy.data.size(); ++i)
    noisy.data[i] = static_cast<float>(((i * 2654435761u) >> 7) % 97 + 80);
  std::vector<uintmax_t> sizes;
  for (int level : {1, 6, 9}) {
    const fs::path dir = root_ / ("level" + std::to_string(level));
    SessionWriterOptions options;
    options.png_compression = level;
    {
      SessionWriter w = SessionWriter::Create(dir, Info(), options);
      w.Append(Meta(Target::kArchitecture, false, 1.0 / 250), noisy);
    }
    const Session s = Session::Load(dir);
    ASSERT_EQ(s.frames().size(), 1u);
    EXPECT_EQ(s.LoadFrame(s.frames()[0]).data, noisy.data) << "level " << level;
    sizes.push_back(fs::file_size(dir / s.frames()[0].file));
  }
  // zlib's levels trade time for size: 9 is never larger than 1.
  EXPECT_LE(sizes[2], sizes[0]);
  SessionWriterOptions bad;
  bad.png_compression = 10;
  EXPECT_THROW(SessionWriter::Create(root_ / "bad", Info(), bad), Error);
  EXPECT_THROW(SessionWriter::Resume(root_ / "level1", bad), Error);
}

TEST_F(SessionTest, CrashLeftoversBeforeSessionJsonDoNotBlockCreateOrResume) {
  // Killed after the folder and frames/ were made, while session.json was being written.
  fs::create_directories(dir_ / "frames");
  WriteFileAtomic(dir_ / "session.json.tmp-1-0", "{\"trunc");
  { SessionWriter w = SessionWriter::Create(dir_, Info()); }
  EXPECT_FALSE(fs::exists(dir_ / "session.json.tmp-1-0"));
  // Killed between session.json and the journal: resume starts an empty journal.
  fs::remove(dir_ / "frames.jsonl");
  SessionWriter w = SessionWriter::Resume(dir_);
  EXPECT_TRUE(w.frames().empty());
  EXPECT_TRUE(fs::exists(dir_ / "frames.jsonl"));
  // Leftovers do not excuse real content.
  const fs::path other = root_ / "other";
  fs::create_directories(other / "frames");
  WriteFileAtomic(other / "frames" / "000001.png", "x");
  EXPECT_THROW(SessionWriter::Create(other, Info()), Error);
}

TEST_F(SessionTest, BadInputsAreRefused) {
  SessionWriter w = SessionWriter::Create(dir_, Info());
  FrameRecord f = Meta(Target::kSky, false, NAN);
  EXPECT_THROW(w.Append(f, Pixels(false, 1)), Error);
  EXPECT_THROW(w.Append(Meta(Target::kSky, false, 1), Image()), Error);
  Image nan = Pixels(true, 1);
  nan.data[3] = NAN;
  EXPECT_THROW(w.Append(Meta(Target::kSky, true, 0), nan), Error);
  EXPECT_TRUE(Session::Load(dir_).frames().empty());
  EXPECT_THROW(SessionWriter::Resume(root_ / "nope"), Error);
  EXPECT_THROW(Session::Load(root_ / "nope"), Error);
  EXPECT_THROW(ParseTarget("Sun"), Error);
  EXPECT_EQ(ParseTarget("aureole"), Target::kAureole);
  for (Target t : {Target::kSun, Target::kAureole, Target::kSky, Target::kLandscape,
                   Target::kArchitecture, Target::kCalibration}) {
    EXPECT_EQ(ParseTarget(TargetName(t)), t);
  }
  // session.json problems name the file.
  json info = json::parse(ReadFileToString(dir_ / "session.json"));
  info["format_version"] = 99;
  WriteFileAtomic(dir_ / "session.json", info.dump());
  ExpectLoadError("session.json");
  info.erase("format_version");
  WriteFileAtomic(dir_ / "session.json", info.dump());
  ExpectLoadError("\"format_version\"");
}

// The surroundings' trees (import --trees) are a list of block names, or absent.
TEST_F(SessionTest, TreesAreBlockNames) {
  SessionInfo with = Info();
  with.trees = {"lime", "plane.2"};
  { SessionWriter w = SessionWriter::Create(dir_, with); }
  EXPECT_EQ(Session::Load(dir_).info().trees, with.trees);
  json info = json::parse(ReadFileToString(dir_ / "session.json"));
  info["trees"] = "lime";
  WriteFileAtomic(dir_ / "session.json", info.dump());
  ExpectLoadError("\"trees\" is not an array of block names");
  info["trees"] = json::array({"lime", 2});
  WriteFileAtomic(dir_ / "session.json", info.dump());
  ExpectLoadError("\"trees\" is not an array of block names");
  info.erase("trees");
  WriteFileAtomic(dir_ / "session.json", info.dump());
  EXPECT_TRUE(Session::Load(dir_).info().trees.empty());
}

// Every journalled frame's file is whole: its sha256 matches and it decodes to its size.
void ExpectWholeFrames(const Session& s, int width, int height) {
  for (const FrameRecord& f : s.frames()) {
    const Image im = s.LoadFrame(f);  // checks the sha256
    EXPECT_EQ(im.width, width) << f.file;
    EXPECT_EQ(im.height, height) << f.file;
  }
}

// Regular files in frames/ (temporaries included).
size_t FilesIn(const fs::path& folder) {
  size_t n = 0;
  for (const auto& e : fs::directory_iterator(folder)) n += e.is_regular_file();
  return n;
}

TEST_F(SessionTest, DiskFullAtAnyCallOfAnAppendLosesNothingJournalled) {
  // How many durable-write calls one append makes (image: open, writes, fsync, rename,
  // directory fsync; journal: write, fsync).
  long calls_per_append = 0;
  {
    SessionWriter w = SessionWriter::Create(dir_, Info());
    w.Append(Meta(Target::kSky, false, 0.01), Pixels(false, 1));
    FaultyFileIo counter;
    ScopedFileIo use(counter);
    w.Append(Meta(Target::kSky, true, 0), Pixels(true, 1));
    calls_per_append = counter.calls();
  }
  ASSERT_GE(calls_per_append, 6);
  for (bool hdr : {false, true}) {
    for (long k = 0; k < calls_per_append; ++k) {
      SCOPED_TRACE((hdr ? "HDR" : "LDR") + std::string(" frame, disk full from call ") +
                   std::to_string(k));
      fs::remove_all(dir_);
      {
        SessionWriter w = SessionWriter::Create(dir_, Info());
        w.Append(Meta(Target::kSky, false, 0.01), Pixels(false, 1));
        w.Append(Meta(Target::kSky, false, 0.02), Pixels(false, 2));
        FaultyFileIo full(k, ENOSPC);
        ScopedFileIo use(full);
        try {
          w.Append(Meta(Target::kSky, hdr, hdr ? 0 : 0.04), Pixels(hdr, 3));
          ADD_FAILURE() << "the append succeeded on a full disk";
        } catch (const Error& e) {
          const std::string m = e.what();
          EXPECT_NE(m.find("the disk is full"), std::string::npos) << m;
          EXPECT_NE(m.find(dir_.string()), std::string::npos) << m;
        }
        EXPECT_EQ(w.frames().size(), 2u);
      }
      // Nothing of the failed frame stays: the journal, the files and the ids end at frame 2.
      Session s = Session::Load(dir_);
      ASSERT_EQ(s.frames().size(), 2u);
      EXPECT_TRUE(s.warnings().empty()) << s.warnings().front();
      ExpectWholeFrames(s, 6, 4);
      EXPECT_EQ(FilesIn(dir_ / "frames"), 2u);
      // Space is back: the session resumes and continues its ids.
      SessionWriter w = SessionWriter::Resume(dir_);
      EXPECT_EQ(w.Append(Meta(Target::kSky, hdr, hdr ? 0 : 0.04), Pixels(hdr, 3)).id, 3);
      w.Close();
      ExpectWholeFrames(Session::Load(dir_), 6, 4);
    }
  }
}

TEST_F(SessionTest, ReadOnlyOrBrokenDiskIsNamedAndLeavesTheSessionConsistent) {
  for (int err : {EROFS, EIO}) {
    fs::remove_all(dir_);
    SessionWriter w = SessionWriter::Create(dir_, Info());
    w.Append(Meta(Target::kSky, false, 0.01), Pixels(false, 1));
    FaultyFileIo broken(0, err, /*short_first_write=*/false);
    ScopedFileIo use(broken);
    try {
      w.Append(Meta(Target::kSky, false, 0.02), Pixels(false, 2));
      ADD_FAILURE();
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(std::strerror(err)), std::string::npos) << e.what();
    }
    EXPECT_EQ(Session::Load(dir_).frames().size(), 1u);
  }
}

TEST_F(SessionTest, OneWriterPerSession) {
  SessionWriter first = SessionWriter::Create(dir_, Info());
  first.Append(Meta(Target::kSky, false, 0.01), Pixels(false, 1));
  // A second writer (resume or create) on the same folder is refused, naming the folder and
  // the holder's pid; the session is untouched.
  for (int attempt = 0; attempt < 2; ++attempt) {
    try {
      if (attempt == 0) {
        SessionWriter::Resume(dir_);
      } else {
        SessionWriter::Create(dir_, Info());
      }
      ADD_FAILURE() << "a second writer got the session";
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(dir_.string()), std::string::npos) << m;
      EXPECT_NE(m.find("in use"), std::string::npos) << m;
      EXPECT_NE(m.find("pid " + std::to_string(::getpid())), std::string::npos) << m;
    }
  }
  EXPECT_EQ(first.Append(Meta(Target::kSky, false, 0.02), Pixels(false, 2)).id, 2);
  first.Close();
  // Released: the next writer continues.
  SessionWriter next = SessionWriter::Resume(dir_);
  EXPECT_EQ(next.Append(Meta(Target::kSky, false, 0.04), Pixels(false, 3)).id, 3);
  ExpectWholeFrames(Session::Load(dir_), 6, 4);
}

TEST_F(SessionTest, IntegersOutOfRangeAreRefusedNotTruncated) {
  FrameRecord f = Meta(Target::kSky, false, 0.01);
  f.gps = GpsFix{};
  f.gps->mode = 3;
  f.file = "frames/000001.png";
  const json good = f;
  EXPECT_EQ(ParseJournalLine(good.dump()).slot, 1);
  auto error_of = [](const std::string& line) -> std::string {
    try {
      ParseJournalLine(line);
    } catch (const Error& e) {
      return e.what();
    }
    return "accepted";
  };
  // Before, slot 4294967297 read as slot 1, gps mode 4294967299 as mode 3, and id
  // 18446744073709551615 as -1.
  json j = good;
  j["slot"] = 4294967297LL;
  EXPECT_NE(error_of(j.dump()).find("\"slot\" is 4294967297, outside"), std::string::npos)
      << error_of(j.dump());
  // Before, slot -1 was taken and `rouen status` died of SIGBUS indexing its slots with it.
  j = good;
  j["slot"] = -1;
  EXPECT_EQ(error_of(j.dump()), "frame record: key \"slot\" must be a slot number 0..1000, not -1");
  j["slot"] = kMaxSlot + 1;
  EXPECT_NE(error_of(j.dump()).find("must be a slot number"), std::string::npos);
  // A frame files into its group's bracket: the group's slot and target are the frame's, and a
  // group names a view. Before, slot 2 with group slot1/... merged into slot 1's bracket.
  j = good;
  j["slot"] = 2;
  EXPECT_EQ(error_of(j.dump()),
            "frame record: group \"slot1/sky/view1\" is slot 1's but key \"slot\" is 2");
  j = good;
  j["target"] = "sun";
  EXPECT_EQ(error_of(j.dump()),
            "frame record: group \"slot1/sky/view1\" is of target sky but key \"target\" is sun");
  j = good;
  j["group"] = "slot1/sky";
  EXPECT_NE(error_of(j.dump()).find("key \"group\": bracket \"slot1/sky\""), std::string::npos)
      << error_of(j.dump());
  j = good;
  j["gps"]["mode"] = 4294967299LL;
  EXPECT_NE(error_of(j.dump()).find("\"mode\" is 4294967299"), std::string::npos);
  j = good;
  j["gps"]["satellites"] = -4294967296LL;
  EXPECT_NE(error_of(j.dump()).find("\"satellites\""), std::string::npos);
  j = good;
  j["id"] = 18446744073709551615ULL;
  EXPECT_NE(error_of(j.dump()).find("\"id\" is 18446744073709551615"), std::string::npos);
  json info = Info();
  info["format_version"] = 4294967297LL;
  try {
    ParseSessionInfo(info.dump(), "s/session.json");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("s/session.json: session info: key \"format_version\""),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace rouen

namespace rouen {
namespace {

// session.json's extra tables: one parser (ParseSessionInfo) and one printer (to_json); what
// they do not know stays in extra as it was.
TEST(SessionInfoTest, TypedExtraTablesRoundTripAndLookUp) {
  const std::string text = R"({"format_version": 1,
    "site": {"lat_deg": 45, "lon_deg": 7, "height_m": 300},
    "extra": {"nd_filters": {"sun": [4.4, 4.5, 4.6], "grey": 2.0,
                             "cal": {"density_rgb": [3.0, 3.1, 3.2], "note": "kept"}},
              "vignetting": {"cam0": {"width": 64, "height": 48, "cx": 32, "cy": 24,
                                      "a": [-0.1, 0, 0]}},
              "sky_masks": {"*": "auto", "slot1/sky/view0": "masks/sky1.png"},
              "heldout_slot": 3, "capture_complete": false,
              "plan": {"slots": ["x"]}}})";
  const SessionInfo info = ParseSessionInfo(text, "session.json");
  ASSERT_EQ(info.nd_filters.size(), 3u);
  EXPECT_EQ(info.nd_filters.at("grey").density_rgb, (std::array<double, 3>{2, 2, 2}));
  EXPECT_EQ(info.heldout_slot, 3);
  EXPECT_EQ(info.capture_complete, false);
  EXPECT_TRUE(info.extra.contains("plan"));
  EXPECT_FALSE(info.extra.contains("nd_filters"));  // typed, not twice
  // The filter whose mean density is within 0.05 of a frame's gives its per-channel
  // transmission; other densities are the frame's own; none in front is 1.
  const auto t = info.NdTransmissionRgb(4.5);
  EXPECT_NEAR(t[0], std::pow(10.0, -4.4), 1e-15);
  EXPECT_NEAR(t[2], std::pow(10.0, -4.6), 1e-15);
  EXPECT_NEAR(info.NdTransmissionRgb(3.1)[2], std::pow(10.0, -3.2), 1e-15);
  for (double v : info.NdTransmissionRgb(2.5)) EXPECT_NEAR(v, std::pow(10.0, -2.5), 1e-15);
  for (double v : info.NdTransmissionRgb(0)) EXPECT_EQ(v, 1);
  ASSERT_NE(info.FindVignetting("cam0", Target::kSky), nullptr);
  EXPECT_EQ(info.FindVignetting("cam1", Target::kSky), nullptr);
  ASSERT_NE(info.FindSkyMask("slot1/sky/view0"), nullptr);
  EXPECT_EQ(info.FindSkyMask("slot1/sky/view0")->file, "masks/sky1.png");
  EXPECT_TRUE(info.FindSkyMask("slot0/sky/view0")->automatic);
  // Printed and parsed again: the same tables, the calibration record kept whole.
  const nlohmann::json printed = info;
  EXPECT_EQ(printed["extra"]["nd_filters"]["cal"]["note"], "kept");
  const SessionInfo again = ParseSessionInfo(printed.dump(), "again");
  EXPECT_EQ(nlohmann::json(again), printed);

  // Each malformed table is an error naming its key.
  auto error_of = [](const std::string& extra) {
    try {
      ParseSessionInfo(R"({"format_version": 1, "site": {"lat_deg": 1, "lon_deg": 2,
                         "height_m": 3}, "extra": )" +
                           extra + "}",
                       "s.json");
    } catch (const Error& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_of(R"({"nd_filters": {"sun": [4, -1, 4]}})").find("nd_filters.sun"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"nd_filters": {"sun": "dark"}})").find("nd_filters.sun"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"nd_filters": [1]})").find("nd_filters must be an object"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"sky_masks": {"*": 3}})").find("sky_masks.*"), std::string::npos);
  EXPECT_NE(error_of(R"({"vignetting": {"cam0": {"model": "nope"}}})").find("vignetting.cam0"),
            std::string::npos);
  EXPECT_NE(error_of(R"({"heldout_slot": -2})").find("heldout_slot"), std::string::npos);
  EXPECT_NE(error_of(R"({"capture_complete": "yes"})").find("capture_complete"), std::string::npos);
}

TEST(BracketNameTest, PrintsAndParsesTheOneKey) {
  EXPECT_EQ(BracketName(2, Target::kArchitecture, 1), "slot2/architecture/view1");
  const BracketKey k = ParseBracketName("slot12/sky/view0");
  EXPECT_EQ(k.slot, 12);
  EXPECT_EQ(k.target, Target::kSky);
  EXPECT_EQ(k.view, 0);
  EXPECT_EQ(BracketName(k), "slot12/sky/view0");
  for (const char* bad :
       {"", "slot1", "slot1/sky", "slotx/sky/view0", "slot1/roof/view0", "slot1/sky/view",
        "slot-1/sky/view0", "slot1/sky/view0/x", "slot99999999/sky/view0"})
    EXPECT_THROW(ParseBracketName(bad), Error) << bad;
}

}  // namespace
}  // namespace rouen
