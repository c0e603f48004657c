// Bad input, told clearly and early: every error names the option, file, line or frame and
// the problem, exits non-zero, and leaves no output and no temporary behind.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <thread>
#include <vector>

#include "core/angles.h"
#include "core/camera.h"
#include "core/files.h"
#include "core/image.h"
#include "core/session.h"
#include "core/solar.h"
#include "core/text.h"
#include "solve/sky_model.h"
#include "tests/cli_util.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::Result;
using cli_test::RunRouen;
using cli_test::TempDir;

// The names in `dir` that are not in `keep` (outputs or temporaries left behind).
std::vector<std::string> Extra(const fs::path& dir, const std::vector<std::string>& keep) {
  std::vector<std::string> out;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    const std::string rel = fs::relative(e.path(), dir).string();
    if (std::find(keep.begin(), keep.end(), rel) == keep.end()) out.push_back(rel);
  }
  return out;
}

// Expects a failure whose output holds every one of `phrases`, and no internal error.
void ExpectError(const Result& r, const std::vector<std::string>& phrases) {
  EXPECT_NE(r.code, 0) << r.out;
  for (const std::string& p : phrases)
    EXPECT_NE(r.out.find(p), std::string::npos) << p << "\n" << r.out;
  EXPECT_EQ(r.out.find("internal error"), std::string::npos) << r.out;
}

// A two-frame LDR bracket with its exposure list and a response curve recovered from it.
struct Bracket {
  fs::path list, response;
};
Bracket MakeBracket(const fs::path& dir) {
  for (int k = 0; k < 2; ++k) {
    Image im(32, 32, 3, PixelUnits::kDigital);
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x)
        for (int c = 0; c < 3; ++c)
          im.at(x, y, c) =
              std::min(250.f, static_cast<float>((8 + 7 * x + 3 * y + 5 * c) * (k + 1) / 2));
    WriteImage((dir / ("f" + std::to_string(k) + ".png")).string(), im, StoredType::kUint8);
  }
  Bracket b{dir / "list.txt", dir / "response.json"};
  WriteFileAtomic(b.list, "f0.png 0.01\nf1.png 0.02\n");
  const Result r = RunRouen("calib response --list " + Q(b.list) + " --out " + Q(b.response));
  EXPECT_EQ(r.code, 0) << r.out;
  return b;
}

// A grey clear sky of eq. 9, as `sky fit` writes one.
fs::path MakeFit(const fs::path& dir) {
  SkyModel m;
  m.sun_dir = EnuFromAzEl(200, 40);
  for (SkyParams& c : m.channel) c = {1.0, -1.0, -0.3, 10.0, -3.0, 0.45, 0.9};
  WriteFileAtomic(dir / "fit.json", nlohmann::json(m).dump());
  return dir / "fit.json";
}

TEST(CliInputs, RadianceIsWrittenOnlyToFloatFormats) {
  const fs::path dir = TempDir("radiance_png");
  const Bracket b = MakeBracket(dir);
  const fs::path fit = MakeFit(dir);
  const std::vector<std::string> inputs = {"f0.png", "f1.png", "list.txt", "response.json",
                                           "fit.json"};
  for (const char* hdr : {"hdr", "calib hdr"}) {
    ExpectError(RunRouen(std::string(hdr) + " --list " + Q(b.list) + " --response " +
                         Q(b.response) + " --out " + Q(dir / "x.png")),
                {"--out", "x.png", "floating-point", ".exr"});
    EXPECT_EQ(Extra(dir, inputs), std::vector<std::string>{}) << hdr;
  }
  ExpectError(RunRouen("sky render " + Q(fit) + " --out " + Q(dir / "sky.png")),
              {"--out", "sky.png", "floating-point"});
  ExpectError(RunRouen("calib envmap --list " + Q(b.list) + " --out " + Q(dir / "env.jpg")),
              {"--out", "env.jpg", "floating-point"});
  ExpectError(RunRouen("calib envmap --list " + Q(b.list) + " --out " + Q(dir / "env.exr") +
                       " --coverage " + Q(dir / "cov.png")),
              {"--coverage", "cov.png", "floating-point"});
  ExpectError(RunRouen("render " + Q(dir / "noscene") + " --slot 0 --out " + Q(dir / "r.png")),
              {"--out", "r.png", "floating-point"});
  EXPECT_EQ(Extra(dir, inputs), std::vector<std::string>{});
  // The same folder is fine as EXR.
  const Result ok = RunRouen("hdr --list " + Q(b.list) + " --response " + Q(b.response) +
                             " --out " + Q(dir / "x.exr"));
  EXPECT_EQ(ok.code, 0) << ok.out;
  EXPECT_EQ(ReadImage((dir / "x.exr").string()).units, PixelUnits::kRadiance);
  // An output that is a folder, or in a missing one, is named before any work.
  ExpectError(
      RunRouen("hdr --list " + Q(b.list) + " --response " + Q(b.response) + " --out " + Q(dir)),
      {"--out " + dir.string(), "is a folder"});
  ExpectError(RunRouen("hdr --list " + Q(b.list) + " --response " + Q(b.response) + " --out " +
                       Q(dir / "missing" / "x.exr")),
              {"--out", "no such folder " + (dir / "missing").string()});
  fs::remove_all(dir);
}

TEST(CliInputs, SitesObeyOneRuleEverywhere) {
  const fs::path dir = TempDir("sites");
  const std::string height = "height 1e+15 m is outside -500..9000 m above the WGS84 ellipsoid";
  const Result sun = RunRouen(
      "sun --lat 37.87 --lon -122.26 --height 1e15 --time "
      "2026-08-25T20:30:00Z");
  ExpectError(sun, {"--height", height});
  EXPECT_EQ(sun.out.find("nan"), std::string::npos) << sun.out;
  ExpectError(RunRouen("sun --lat 91 --lon 0 --time 2026-08-25T20:30:00Z"),
              {"--lat", "latitude 91 deg is outside -90..90 deg"});
  ExpectError(RunRouen("sun --lat 37 --lon 0 --height nan --time 2026-08-25T20:30:00Z"),
              {"--height", "'nan' is not a number"});
  WriteFileAtomic(dir / "fixes.csv",
                  "utc,lat,lon,elev_m\n2026-08-25T20:30:00Z,37.8722,-122.2578,60\n"
                  "2026-08-25T20:30:00Z,37.8722,-122.2578,1e15\n");
  const Result batch = RunRouen("sun --batch " + Q(dir / "fixes.csv"));
  ExpectError(batch, {"fixes.csv:3: " + height});
  EXPECT_EQ(batch.out.find("nan"), std::string::npos) << batch.out;
  fs::create_directories(dir / "photos");
  ExpectError(RunRouen("import --photos " + Q(dir / "photos") + " --site 38.6,-90.2,1e15 --out " +
                       Q(dir / "s")),
              {"--site", height});
  ExpectError(RunRouen("calib orient --image a.exr --lens l.json --time 2026-08-25T20:30:00Z "
                       "--level --site 37.87,-122.26,1e15 --out " +
                       Q(dir / "pose.json")),
              {"--site", height});
  EXPECT_EQ(Extra(dir, {"fixes.csv", "photos"}), std::vector<std::string>{});
  fs::remove_all(dir);
}

TEST(CliInputs, NumericOptionsRefuseNonsenseBeforeAnyWork) {
  struct Case {
    std::string args, option;
  };
  // Required arguments name files that need not exist: the option is refused first.
  const std::string sky_fit =
      "sky fit --image none.exr --projection equirect --sun-azimuth 10 --sun-elevation 30 "
      "--out none.json ";
  const std::string render = "render none --out none.exr ";
  const std::vector<Case> cases = {
      {"sun --lat 1 --lon 1 --time 2026-08-25T20:30:00Z --pressure nan", "--pressure"},
      {"sun --lat 1 --lon 1 --time 2026-08-25T20:30:00Z --pressure -5", "--pressure"},
      {"sun --lat 1 --lon 1 --time 2026-08-25T20:30:00Z --temperature 1e9", "--temperature"},
      {"sun --lat 1 --lon inf --time 2026-08-25T20:30:00Z", "--lon"},
      {render + "--slot -1", "--slot"},
      {render + "--time 2026-08-25T20:30:00Z --pbs nan", "--pbs"},
      {render + "--time 2026-08-25T20:30:00Z --overcast-brightness nan", "--overcast-brightness"},
      {render + "--time 2026-08-25T20:30:00Z --overcast-colour 1,-1,1", "--overcast-colour"},
      {render + "--slot 0 --png none.png --exposure -1", "--exposure"},
      {render + "--slot 0 --png none.png --exposure nan", "--exposure"},
      {"sky render none.json --out none.exr --width -2", "--width"},
      {"sky render none.json --out none.exr --azimuth-offset nan", "--azimuth-offset"},
      {sky_fit + "--min-elevation nan", "--min-elevation"},
      {sky_fit + "--sun-exclusion -1", "--sun-exclusion"},
      {sky_fit + "--max-samples 0", "--max-samples"},
      {"calib response --list none.txt --out none.json --samples -5", "--samples"},
      {"calib response --list none.txt --out none.json --lambda nan", "--lambda"},
      {"calib envmap --list none.txt --out none.exr --width 0", "--width"},
      {"calib envmap --list none.txt --out none.exr --supersample 99", "--supersample"},
      {"calib envmap --list none.txt --out none.exr --feather nan", "--feather"},
      {"calib orient --image a.exr --lens l.json --time 2026-08-25T20:30:00Z --site 1,1,1 "
       "--level --out none.json --landmark-sigma -1",
       "--landmark-sigma"},
      {"calib pose --points p.json --lens l.json --out none.json --threshold nan", "--threshold"},
      {"calib nd --with a.txt --without b.txt --out none.json --min-level -0.5", "--min-level"},
      {"calib vignetting --flat a.txt --out none.json --bin 0", "--bin"},
      {"calib intrinsics --images a --board chessboard:9x7:0.025 --out none.json --min-views 0",
       "--min-views"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.args);
    const Result r = RunRouen(c.args);
    ExpectError(r, {c.option});
    EXPECT_EQ(r.out.find("none."), std::string::npos) << "a file was read first: " << r.out;
  }
}

TEST(CliInputs, RenderArgumentErrorsComeFirstAndNameTheOption) {
  const fs::path dir = TempDir("render_args");
  const std::string base = "render " + Q(dir / "none") + " --out " + Q(dir / "r.exr");
  ExpectError(RunRouen(base + " --slot 0 --overcast-brightness 1"),
              {"--overcast-brightness", "--slot"});
  ExpectError(RunRouen(base + " --slot 0 --pbs 0"), {"--pbs", "--slot"});
  ExpectError(RunRouen(base + " --slot 0 --exposure 2"), {"--exposure", "--png"});
  ExpectError(RunRouen(base + " --slot 0 --time 2026-08-25T20:30:00Z"), {"--slot", "--time"});
  ExpectError(RunRouen(base + " --slot 0 --png " + Q(dir / "missing" / "r.png")),
              {"--png", "no such folder"});
  // NaN is not "no height given".
  ExpectError(
      RunRouen("envmap " + Q(dir / "none") + " --slot 0 --height nan --out " + Q(dir / "e.exr")),
      {"--height", "'nan' is not a number within"});
  fs::path work_file = dir / "work";
  WriteFileAtomic(work_file, "a file, not a folder\n");
  ExpectError(RunRouen("solve " + Q(dir / "none") + " --out " + Q(dir / "s.scene") + " --work " +
                       Q(work_file)),
              {"--work " + work_file.string(), "not a folder"});
  // A scene's name is checked before the session is read.
  ExpectError(RunRouen("solve " + Q(dir / "none") + " --out " + Q(work_file)),
              {work_file.string(), "not a folder"});
  ExpectError(RunRouen("solve " + Q(dir / "none") + " --out " + Q(dir / "missing" / "s.scene")),
              {"missing", "does not exist"});
  ExpectError(RunRouen("solve " + Q(dir / "none") + " --out " + Q(dir / "s.scene")),
              {(dir / "none").string()});
  // A solve configuration is read before the session; a misspelt key is named.
  WriteFileAtomic(dir / "solve.toml", "[sky_fit]\nnorm = 2\n");
  ExpectError(RunRouen("solve " + Q(dir / "none") + " --out " + Q(dir / "s.scene") + " --config " +
                       Q(dir / "solve.toml")),
              {"solve.toml: sky_fit.norm is not a known key"});
  ExpectError(RunRouen("solve --out " + Q(dir / "s.scene")), {"needs a SESSION folder"});
  // --print-config shows every option with the file applied.
  WriteFileAtomic(dir / "solve.toml", "[sky_fit]\nnorm_p = 2\n");
  const Result printed = RunRouen("solve --quick --print-config --config " + Q(dir / "solve.toml"));
  EXPECT_EQ(printed.code, 0) << printed.out;
  const nlohmann::json config = nlohmann::json::parse(printed.out);
  EXPECT_EQ(config["sky_fit"]["norm_p"], 2.0);
  EXPECT_EQ(config["response"]["max_brackets"], 6);
  EXPECT_EQ(Extra(dir, {"work", "solve.toml"}), std::vector<std::string>{});
  fs::remove_all(dir);
}

// A rig's [solve] options are checked before the capture starts: a misspelt key is named
// with the rig file, and no session is started.
TEST(CliInputs, ARigsSolveOptionsAreCheckedBeforeTheCapture) {
  const fs::path dir = TempDir("rigsolve");
  WriteFileAtomic(
      dir / "rig.toml",
      ReadFileToString(fs::path(ROUEN_SOURCE_DIR) / "rigs" / "sim.toml") + "grid.spacing = 1\n");
  ExpectError(RunRouen("capture --rig " + Q(dir / "rig.toml") + " --out " + Q(dir / "s") +
                       " --no-prompt --quick"),
              {"rig.toml: [solve]: grid.spacing is not a known key"});
  EXPECT_FALSE(fs::exists(dir / "s"));
  fs::remove_all(dir);
}

// A simulated plan with a slot at night is refused before the session is made, naming the
// slot, its time and the sun's depth; --allow-night is the rehearsal's way through.
TEST(CliInputs, ACapturePlannedAtNightIsRefusedBeforeAnyFrame) {
  const fs::path dir = TempDir("night");
  std::string rig = ReadFileToString(fs::path(ROUEN_SOURCE_DIR) / "rigs" / "sim.toml");
  const size_t times = rig.find("times = [");
  ASSERT_NE(times, std::string::npos);
  rig.replace(times, rig.find('\n', times) - times, "times = [\"13:30\", \"23:30\"]");
  const size_t heldout = rig.find("heldout = ");
  ASSERT_NE(heldout, std::string::npos);
  rig.erase(heldout, rig.find('\n', heldout) + 1 - heldout);
  WriteFileAtomic(dir / "rig.toml", rig);
  // 23:30 PDT on 2026-08-25 is 06:30 UTC the next day, the sun 25-30 deg below Berkeley's horizon.
  ExpectError(
      RunRouen("capture --rig " + Q(dir / "rig.toml") + " --out " + Q(dir / "s") +
               " --no-prompt --quick"),
      {"slot 1 at 2026-08-26T06:30:00Z: the sun is", "deg below the horizon", "--allow-night"});
  EXPECT_FALSE(fs::exists(dir / "s"));
  fs::remove_all(dir);
}

// A new session or scene is never made inside another session or scene folder, nor a render
// camera's size given where the camera is a view's own.
TEST(CliInputs, NewFoldersStayOutOfSessionsAndScenes) {
  const fs::path dir = TempDir("nested");
  fs::create_directories(dir / "s");
  WriteFileAtomic(dir / "s" / "session.json", "{}");
  fs::create_directories(dir / "sc");
  WriteFileAtomic(dir / "sc" / "scene.json", "{}");
  fs::create_directories(dir / "photos");
  ExpectError(RunRouen("import --photos " + Q(dir / "photos") + " --site 1,2,3 --out " +
                       Q(dir / "sc" / "new")),
              {"lies inside the scene " + (dir / "sc").string()});
  ExpectError(RunRouen("solve " + Q(dir / "s") + " --out " + Q(dir / "sc" / "inner")),
              {"lies inside the scene " + (dir / "sc").string()});
  ExpectError(RunRouen("capture --rig " + Q(fs::path(ROUEN_SOURCE_DIR) / "rigs" / "sim.toml") +
                       " --out " + Q(dir / "s" / "more") + " --no-prompt --quick"),
              {"lies inside the session " + (dir / "s").string()});
  ExpectError(RunRouen("view " + Q(dir / "sc") + " --out " + Q(dir / "sc" / "view")),
              {"lies inside the scene " + (dir / "sc").string()});
  EXPECT_FALSE(fs::exists(dir / "sc" / "view"));
  EXPECT_FALSE(fs::exists(dir / "sc" / "new"));
  EXPECT_FALSE(fs::exists(dir / "sc" / "inner"));
  EXPECT_FALSE(fs::exists(dir / "s" / "more"));
  ExpectError(
      RunRouen("render " + Q(dir / "sc") + " --slot 0 --size 64x48 --out " + Q(dir / "r.exr")),
      {"--size sets the --look-at camera"});
  fs::remove_all(dir);
}

// An output that cannot be written is named as the user gave it, not by its temporary name,
// with the cause: a sky fit whose zenith radiance is 1e308 overflows where it is rendered.
TEST(CliInputs, AFailedOutputIsNamedAsGivenWithItsCause) {
  const fs::path dir = TempDir("overflow");
  std::string csv;
  for (int el = 5, k = 0; el < 90; el += 10) {
    for (int az = 0; az < 360; az += 30, ++k) {
      const double r = 1 + 0.5 * std::cos(az * kDeg) * std::cos(el * kDeg);
      csv += Formatted("%d, %d, %d, %.4f, %.4f, %.4f\n", k, az, el, r, 1.1 * r, 1.3 * r);
    }
  }
  WriteFileAtomic(dir / "scan.csv", csv);
  const Result fit = RunRouen("sky fit --samples " + Q(dir / "scan.csv") +
                              " --sun-azimuth 180 --sun-elevation 40 --out " + Q(dir / "fit.json"));
  ASSERT_EQ(fit.code, 0) << fit.out;
  nlohmann::json j = nlohmann::json::parse(ReadFileToString(dir / "fit.json"));
  for (auto& channel : j["channels"]) channel["Lz"] = 1e308;
  WriteFileAtomic(dir / "fit.json", j.dump());
  const fs::path out = dir / "sky.exr";
  const Result r = RunRouen("sky render " + Q(dir / "fit.json") + " --out " + Q(out));
  ExpectError(r, {"rouen: error: " + out.string() + ": refusing to write a non-finite value",
                  "overflowed"});
  EXPECT_EQ(r.out.find(".tmp-"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(out));
  fs::remove_all(dir);
}

TEST(CliInputs, ListsAndCsvWithAByteOrderMarkAreRead) {
  const fs::path dir = TempDir("bom");
  const std::string csv = "utc,lat,lon,elev_m\n2026-08-25T20:30:00Z,37.8722,-122.2578,60\n";
  WriteFileAtomic(dir / "plain.csv", csv);
  WriteFileAtomic(dir / "bom.csv", "\xEF\xBB\xBF" + csv);
  const Result plain = RunRouen("sun --batch " + Q(dir / "plain.csv"));
  const Result bom = RunRouen("sun --batch " + Q(dir / "bom.csv"));
  ASSERT_EQ(plain.code, 0) << plain.out;
  EXPECT_EQ(bom.code, 0) << bom.out;
  EXPECT_EQ(bom.out, plain.out);
  const Bracket b = MakeBracket(dir);
  WriteFileAtomic(dir / "bom.txt", "\xEF\xBB\xBF" + ReadFileToString(b.list));
  const Result r =
      RunRouen("calib response --list " + Q(dir / "bom.txt") + " --out " + Q(dir / "r2.json"));
  EXPECT_EQ(r.code, 0) << r.out;
  fs::remove_all(dir);
}

TEST(CliInputs, ExposureListsNameTheLineAndTheRange) {
  const fs::path dir = TempDir("exposures");
  const Bracket b = MakeBracket(dir);
  WriteFileAtomic(dir / "huge.txt", "f0.png 0.01\n# a comment\nf1.png 1e308\n");
  ExpectError(RunRouen("hdr --list " + Q(dir / "huge.txt") + " --response " + Q(b.response) +
                       " --out " + Q(dir / "x.exr")),
              {"huge.txt:3: exposure 1e+308 s is outside 1e-09..86400 s"});
  fs::create_directories(dir / "photos");
  fs::copy(dir / "f0.png", dir / "photos" / "a.png");
  WriteFileAtomic(dir / "import.txt", "a.png 1e308 2026-08-25T20:30:00Z\n");
  ExpectError(RunRouen("import --photos " + Q(dir / "photos") + " --list " + Q(dir / "import.txt") +
                       " --site 37,-122,10 --out " + Q(dir / "s")),
              {"import.txt:1: exposure 1e+308 s is outside"});
  EXPECT_FALSE(fs::exists(dir / "x.exr"));
  EXPECT_FALSE(fs::exists(dir / "s"));
  fs::remove_all(dir);
}

// Envmap's four outputs are written together or not at all.
TEST(CliInputs, EnvmapLeavesNoOutputWhenOneCannotBeWritten) {
  const fs::path dir = TempDir("envmap_all");
  const Intrinsics k = Intrinsics::PinholeFov(40, 30, 70);
  Image img(k.width, k.height, 3, PixelUnits::kRadiance, 1.f);
  WriteImage((dir / "p.exr").string(), img, StoredType::kFloat);
  const nlohmann::json lens = k, pose = Pose::Level(Eigen::Vector3d::Zero(), 90, 0);
  WriteFileAtomic(dir / "p.lens.json", lens.dump());
  WriteFileAtomic(dir / "p.pose.json", pose.dump());
  WriteFileAtomic(dir / "photos.txt", "p.exr p.lens.json p.pose.json\n");
  ExpectError(RunRouen("calib envmap --list " + Q(dir / "photos.txt") + " --width 64 --out " +
                       Q(dir / "env.exr") + " --summary " + Q(dir / "missing" / "env.json")),
              {"--summary", "no such folder"});
  EXPECT_EQ(Extra(dir, {"p.exr", "p.lens.json", "p.pose.json", "photos.txt"}),
            std::vector<std::string>{});
  fs::remove_all(dir);
}

// A one-slot simulated session, captured once; each test edits a copy of it.
class CliSessionInputs : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(TempDir("session_inputs"));
    WriteFileAtomic(*root_ / "rig.toml", cli_test::OneSlotRig());
    const int rc = cli_test::Wait(
        cli_test::Spawn({ROUEN_BINARY, "capture", "--rig", (*root_ / "rig.toml").string(), "--out",
                         (*root_ / "s").string(), "--quick", "--no-prompt"},
                        *root_ / "capture.log"));
    ASSERT_EQ(rc, 0) << ReadFileToString(*root_ / "capture.log");
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
  }
  // A copy of the session named `name`.
  fs::path Copy(const std::string& name) {
    const fs::path dir = *root_ / name;
    fs::remove_all(dir);
    fs::copy(*root_ / "s", dir, fs::copy_options::recursive);
    return dir;
  }
  // Replaces the first match of `pattern` in `file` by `by`.
  static void Edit(const fs::path& file, const std::string& pattern, const std::string& by) {
    const std::string text = ReadFileToString(file);
    const std::string edited =
        std::regex_replace(text, std::regex(pattern), by, std::regex_constants::format_first_only);
    ASSERT_NE(edited, text) << pattern;
    WriteFileAtomic(file, edited);
  }
  // `rouen solve` of the session: must fail naming every one of `phrases`, write no scene,
  // and (`before_any_work`) no HDR merge into the working folder.
  static void ExpectSolveError(const fs::path& s, const std::vector<std::string>& phrases,
                               bool before_any_work = true) {
    const fs::path scene = s.string() + ".scene";
    ExpectError(RunRouen("solve " + Q(s) + " --out " + Q(scene)), phrases);
    EXPECT_FALSE(fs::exists(scene));
    if (before_any_work) {
      EXPECT_FALSE(fs::exists(scene.string() + ".work/calib")) << s;
    }
  }
  static fs::path* root_;
};
fs::path* CliSessionInputs::root_ = nullptr;

TEST_F(CliSessionInputs, JournalValuesOutOfRangeNameTheFrame) {
  const fs::path nd = Copy("nd");
  Edit(nd / "frames.jsonl", "\"nd_density\":4.5", "\"nd_density\":-1");  // frame 1, the sun
  ExpectSolveError(nd, {(nd / "frames.jsonl").string(), "frame 1", "slot0/sun/view0",
                        "ND density -1 is outside 0..10"});
  const fs::path ex = Copy("exposure");
  // The first frame exposed 1/256 s: frame 2, the sun's second.
  Edit(ex / "frames.jsonl", "\"exposure_s\":0.00390625", "\"exposure_s\":1e308");
  ExpectSolveError(ex, {(ex / "frames.jsonl").string(), "frame 2", "slot0/sun/view0",
                        "exposure 1e+308 s is outside 1e-09..86400 s"});
}

TEST_F(CliSessionInputs, AFrameOfTheWrongSizeNamesItsFileAndBracket) {
  const fs::path s = Copy("tiny");
  // A frame journalled with its hash (as an import of a 1x1 photo would), so that the size
  // check, not the sha256 check, is what refuses it.
  const std::string before = Sha256File(s / "frames" / "000008.png");
  Image one(1, 1, 3, PixelUnits::kDigital, 100.f);
  WriteImage((s / "frames" / "000008.png").string(), one, StoredType::kUint8);
  Edit(s / "frames.jsonl", before, Sha256File(s / "frames" / "000008.png"));
  const Session session = Session::Load(s);
  const FrameRecord& f = session.frames()[7];
  ASSERT_EQ(f.id, 8);
  ExpectSolveError(
      s,
      {"frame 8", "frames/000008.png", f.group, "1x1",
       std::to_string(f.intrinsics->width) + "x" + std::to_string(f.intrinsics->height)},
      /*before_any_work=*/false);
}

TEST_F(CliSessionInputs, AModelWithoutFacesIsRefusedBeforeAnyWork) {
  const fs::path s = Copy("empty_model");
  WriteFileAtomic(s / "model.obj", "# exported from nowhere\n\n");
  ExpectSolveError(s, {(s / "model.obj").string(), "no faces"});
}

TEST_F(CliSessionInputs, TheSessionSiteObeysTheHeightRule) {
  const fs::path gps = Copy("gps_height");
  Edit(gps / "frames.jsonl", "\"height_m\":[0-9.e+-]+", "\"height_m\":1e15");
  ExpectSolveError(gps, {"frames.jsonl", "GPS", "height", "is outside -500..9000 m"});
  const fs::path site = Copy("site_height");
  const std::string journal = ReadFileToString(site / "frames.jsonl");
  WriteFileAtomic(site / "frames.jsonl",
                  std::regex_replace(journal, std::regex("\"gps\":\\{[^}]*\\}"),
                                     "\"gps\":null"));  // no fix: session.json's site counts
  Edit(site / "session.json", "\"height_m\": [0-9.e+-]+", "\"height_m\": 1e15");
  ExpectSolveError(site, {(site / "session.json").string(),
                          "height 1e+15 m is outside -500..9000 m above the WGS84 ellipsoid"});
}

// Ctrl-C or SIGTERM while a radiance file is being made: the process ends as the signal says
// and leaves neither the output nor a temporary.
TEST(CliInputs, ASignalLeavesNoTemporaryAndNoOutput) {
  const fs::path dir = TempDir("signal");
  const fs::path fit = MakeFit(dir);
  for (int sig : {SIGTERM, SIGINT}) {
    SCOPED_TRACE(sig);
    const fs::path out = dir / "sky.exr";
    const pid_t pid = cli_test::Spawn(
        {ROUEN_BINARY, "sky", "render", fit.string(), "--out", out.string(), "--width", "8192"},
        dir / "log.txt");
    // Wait until a temporary exists (or the process ends, which fails the test).
    bool seen = false;
    int status = 0;
    while (!seen) {
      for (const auto& e : fs::directory_iterator(dir))
        if (e.path().filename().string().find(".tmp-") != std::string::npos) seen = true;
      if (seen) break;
      const pid_t done = ::waitpid(pid, &status, WNOHANG);
      ASSERT_EQ(done, 0) << "ended before a temporary was seen: "
                         << ReadFileToString(dir / "log.txt");
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    ASSERT_EQ(::kill(pid, sig), 0);
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == sig)
        << "status " << status << ": " << ReadFileToString(dir / "log.txt");
    EXPECT_EQ(Extra(dir, {"fit.json", "log.txt"}), std::vector<std::string>{});
  }
  fs::remove_all(dir);
}

}  // namespace
}  // namespace rouen
