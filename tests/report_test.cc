// rouen report end to end: the quick demo writes its report; `rouen report` writes one from the
// demo's folders and from a scene missing its optional parts; headless Chromium opens the
// page, which must load whole offline (every image decoded, no console error, nothing fetched
// from elsewhere, every section and plot there), and its screenshot is kept.
#include <gtest/gtest.h>

#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "core/files.h"
#include "core/image.h"
#include "core/session.h"
#include "tests/cli_util.h"
#include "tests/devtools.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::RunRouen;

const std::vector<std::string> kSections = {"overview", "timeline",   "sunpath",
                                            "response", "sky",        "environment",
                                            "albedo",   "validation", "timings"};

// One quick demo shared by the tests (its report among its outputs).
class ReportCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(cli_test::TempDir("report"));
    demo_ = new cli_test::Result(RunRouen("demo --quick --out " + Q(*root_ / "demo")));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
    delete demo_;
  }
  void SetUp() override { ASSERT_EQ(demo_->code, 0) << demo_->out; }
  static fs::path Demo() { return *root_ / "demo"; }
  static fs::path* root_;
  static cli_test::Result* demo_;
};
fs::path* ReportCli::root_ = nullptr;
cli_test::Result* ReportCli::demo_ = nullptr;

TEST_F(ReportCli, TheDemoWritesItsReportAndSaysWhere) {
  const fs::path report = Demo() / "report.html";
  EXPECT_NE(demo_->out.find("report: " + report.string()), std::string::npos) << demo_->out;
  ASSERT_TRUE(fs::is_regular_file(report));
  const std::string html = ReadFileToString(report);
  for (const std::string& id : kSections)
    EXPECT_NE(html.find("<section id=\"" + id + "\">"), std::string::npos) << id;
  // The demo's held-out photographs beside their renders, and its figures.
  EXPECT_NE(html.find("<h3>slot3/architecture/view0</h3>"), std::string::npos);
  EXPECT_NE(html.find("heldout_render_psnr_db"), std::string::npos);
  // Everything the demo has is shown: the only gap is what no scene records.
  EXPECT_EQ(html.find("could not be completed"), std::string::npos);
  EXPECT_EQ(html.find("No session given"), std::string::npos);
  EXPECT_EQ(html.find("give --work"), std::string::npos);
  EXPECT_EQ(html.find("No validation results"), std::string::npos);
}

TEST_F(ReportCli, ReportCommandOnTheDemoScene) {
  const fs::path out = *root_ / "cli" / "report.html";
  fs::create_directories(out.parent_path());
  const cli_test::Result r =
      RunRouen("report " + Q(Demo() / "scene") + " --session " + Q(Demo() / "session") +
               " --work " + Q(Demo() / "work") + " --metrics " + Q(Demo() / "metrics.json") +
               " --validate 3 --exclude-block plaza --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("wrote " + out.string()), std::string::npos) << r.out;
  const std::string html = ReadFileToString(out);
  EXPECT_NE(html.find("<h3>slot3/architecture/view0</h3>"), std::string::npos);
  EXPECT_NE(html.find("Sky fit error by elevation"), std::string::npos);
  EXPECT_NE(html.find("Exposure of every frame"), std::string::npos);
  // Nothing but the report was written beside it.
  EXPECT_EQ(std::distance(fs::directory_iterator(out.parent_path()), fs::directory_iterator()), 1);
}

TEST_F(ReportCli, ASceneWithoutItsOptionalPartsIsReportedWithWhatIsMissing) {
  const fs::path scene = *root_ / "bare.scene";
  fs::remove_all(scene);
  fs::copy(Demo() / "scene", scene, fs::copy_options::recursive);
  fs::remove_all(scene / "atlas");
  nlohmann::json j = nlohmann::json::parse(ReadFileToString(scene / "scene.json"));
  j["timings"] = nullptr;
  j["response"] = nullptr;
  WriteFileAtomic(scene / "scene.json", j.dump(1));
  const fs::path out = *root_ / "bare.html";
  const cli_test::Result r = RunRouen("report " + Q(scene) + " --out " + Q(out));
  ASSERT_EQ(r.code, 0) << r.out;
  for (const char* said : {"Capture timeline: No session given (--session)",
                           "Camera response: scene.json records no "
                           "response curve",
                           "Sky fits: The error by elevation", "Validation: No validation results",
                           "Timings: scene.json records no timings", "baked from the albedo grids"})
    EXPECT_NE(r.out.find(said), std::string::npos) << said << "\n" << r.out;
  const std::string html = ReadFileToString(out);
  EXPECT_NE(html.find("<p class=\"absent\">"), std::string::npos);
  for (const std::string& id : kSections)
    EXPECT_NE(html.find("<section id=\"" + id + "\">"), std::string::npos) << id;
}

TEST_F(ReportCli, ErrorsNameTheProblemAndWriteNothing) {
  const fs::path out = *root_ / "err.html";
  cli_test::Result r = RunRouen("report " + Q(*root_ / "nowhere") + " --out " + Q(out));
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("no such scene folder"), std::string::npos) << r.out;
  r = RunRouen("report " + Q(Demo() / "scene") + " --validate 3 --out " + Q(out));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("--validate needs --session"), std::string::npos) << r.out;
  r = RunRouen("report " + Q(Demo() / "scene") + " --out " + Q(*root_ / "missing" / "r.html"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("--out"), std::string::npos) << r.out;
  r = RunRouen("report " + Q(Demo() / "scene") + " --metrics " + Q(*root_ / "no.json") + " --out " +
               Q(out));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("no.json"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(*root_ / "missing"));
}

// The demo's report in headless Chromium, offline: every image decoded, no console error or
// failed load, nothing requested but the page and its inline data, each section there with the
// plots and series it should have. The screenshot is kept in the build folder.
TEST_F(ReportCli, OpensWholeInHeadlessChromium) {
  const std::optional<std::string> chromium = devtools::FindChromium();
  if (!chromium)
    GTEST_SKIP() << "chromium is not installed (Debian: apt-get install chromium; ./dev test "
                    "installs it): the report was not opened in a browser";
  const fs::path report = fs::absolute(Demo() / "report.html");
  const std::string url = "file://" + report.string();
  nlohmann::json checks;
  std::vector<std::string> errors, requests;
  {
    devtools::Browser browser(*chromium, *root_ / "chromium-profile", *root_ / "chromium.log");
    browser.OpenPage();
    for (const char* domain : {"Page", "Runtime", "Log", "Network"})
      browser.Call(std::string(domain) + ".enable");
    browser.Call("Emulation.setDeviceMetricsOverride",
                 {{"width", 1280}, {"height", 4000}, {"deviceScaleFactor", 1}, {"mobile", false}});
    browser.ClearEvents();
    browser.Call("Page.navigate", {{"url", url}});
    browser.WaitEvent("Page.loadEventFired");
    const nlohmann::json r = browser.Call(
        "Runtime.evaluate", {{"returnByValue", true}, {"expression", R"(JSON.stringify({
           images: [...document.images].map(i => ({alt: i.alt, ok: i.complete && i.naturalWidth > 0})),
           sections: [...document.querySelectorAll('section')].map(s => s.id),
           series: Object.fromEntries([...document.querySelectorAll('section')].map(s =>
             [s.id, [...s.querySelectorAll('svg.plot')].map(v => v.querySelectorAll('g.series').length)])),
           height: document.documentElement.scrollHeight}))"}});
    checks = nlohmann::json::parse(r.at("result").at("value").get<std::string>());
    const nlohmann::json shot = browser.Call("Page.captureScreenshot", {{"format", "png"}});
    const fs::path build = fs::path(ROUEN_BINARY).parent_path().parent_path();
    WriteFileAtomic(build / "report_screenshot.png",
                    devtools::DecodeBase64(shot.at("data").get<std::string>()));
    const nlohmann::json small = browser.Call(
        "Page.captureScreenshot",
        {{"format", "png"},
         {"clip", {{"x", 0}, {"y", 0}, {"width", 1280}, {"height", 4000}, {"scale", 0.6}}}});
    WriteFileAtomic(build / "report_screenshot_small.png",
                    devtools::DecodeBase64(small.at("data").get<std::string>()));
    for (const nlohmann::json& e : browser.events()) {
      const std::string m = e.value("method", "");
      const nlohmann::json& p = e.value("params", nlohmann::json::object());
      if (m == "Runtime.exceptionThrown") errors.push_back(p.dump());
      if (m == "Runtime.consoleAPICalled" &&
          (p.value("type", "") == "error" || p.value("type", "") == "assert"))
        errors.push_back(p.dump());
      if (m == "Log.entryAdded" && p["entry"].value("level", "") == "error")
        errors.push_back(p.dump());
      if (m == "Network.requestWillBeSent") requests.push_back(p["request"].value("url", ""));
    }
    const fs::path shot_file = build / "report_screenshot.png";
    const Image png = ReadImage(shot_file.string());
    EXPECT_EQ(png.width, 1280);
    EXPECT_EQ(png.height, 4000);
  }
  EXPECT_TRUE(errors.empty()) << nlohmann::json(errors).dump(1);
  for (const std::string& u : requests)
    EXPECT_TRUE(u == url || u.rfind("data:", 0) == 0) << "the page requested " << u;
  // Every image loaded.
  ASSERT_GE(checks["images"].size(), 20u) << checks.dump();
  for (const nlohmann::json& i : checks["images"]) EXPECT_TRUE(i["ok"].get<bool>()) << i.dump();
  // Every section, in order, with its plots and their series.
  EXPECT_EQ(checks["sections"].get<std::vector<std::string>>(), kSections);
  const Session session = Session::Load(Demo() / "session");
  std::set<Target> targets;
  for (const FrameRecord& f : session.frames()) targets.insert(f.target);
  const nlohmann::json scene =
      nlohmann::json::parse(ReadFileToString(Demo() / "scene" / "scene.json"));
  const int slots = static_cast<int>(scene["slots"].size());
  // One plot of the sun lobes, a curve per glossy block, when some block has one.
  const int lobes = static_cast<int>(scene["albedo"]["sun_lobes"].size());
  const std::vector<int> albedo_plots = lobes ? std::vector<int>{lobes} : std::vector<int>{};
  const std::map<std::string, std::vector<int>> expected = {
      {"overview", {}},
      {"timeline", {static_cast<int>(targets.size())}},
      {"sunpath", {3}},  // the path, the captured slots, the held-out slot
      {"response", {3}},
      {"sky", {slots, slots, slots, slots}},  // Bg, Sa; error by elevation, by angle from the sun
      {"environment", {}},
      {"albedo", albedo_plots},
      {"validation", {}},
      {"timings", {1}}};
  for (const auto& [id, series] : expected)
    EXPECT_EQ(checks["series"][id].get<std::vector<int>>(), series) << id;
  EXPECT_GT(checks["height"].get<int>(), 4000);
}

}  // namespace
}  // namespace rouen
