// rouen view end to end: the page and its data written for a small scene, then opened in
// headless Chromium (software WebGL): it must start without a console error, create its WebGL
// context, and relight the building as rouen render does -- through the page's own camera, at
// a morning and an evening time and under overcast, each screenshot is compared with rouen
// render's image of the same camera, time and exposure. The screenshots and the renders are
// kept in the build folder (view_*.png).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "core/files.h"
#include "core/image.h"
#include "core/limits.h"
#include "core/response_curve.h"
#include "pipeline/export_test_util.h"
#include "render/tonemap.h"
#include "tests/cli_util.h"
#include "tests/devtools.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;
using cli_test::Q;
using cli_test::RunRouen;

constexpr int kTimes = 6;
constexpr int kWidth = 480, kHeight = 360;

class ViewCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(cli_test::TempDir("view"));
    testing::WriteExportTestScene(*root_ / "scene");
    run_ =
        new cli_test::Result(RunRouen("view " + Q(*root_ / "scene") + " --out " +
                                      Q(*root_ / "view") + " --times " + std::to_string(kTimes)));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
    delete run_;
  }
  void SetUp() override { ASSERT_EQ(run_->code, 0) << run_->out; }
  static fs::path* root_;
  static cli_test::Result* run_;
};
fs::path* ViewCli::root_ = nullptr;
cli_test::Result* ViewCli::run_ = nullptr;

TEST_F(ViewCli, WritesThePageAndItsDataWhole) {
  EXPECT_NE(run_->out.find("index.html: " + std::to_string(kTimes) + " times"), std::string::npos)
      << run_->out;
  const fs::path view = *root_ / "view";
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(view)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"index.html", "viewer_data.js"}));
  // Nothing half-written beside it.
  for (const auto& e : fs::directory_iterator(*root_))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
  const std::string js = ReadFileToString(view / "viewer_data.js");
  EXPECT_LT(js.size(), 2u << 20);  // the small scene: well under 2 MB
  const nlohmann::json j =
      nlohmann::json::parse(js.substr(js.find('=') + 1, js.rfind(';') - js.find('=') - 1));
  ASSERT_EQ(j["bases"].size(), static_cast<size_t>(kTimes));
  EXPECT_EQ(j["camera_from_view"], "slot0/architecture/view0");
  EXPECT_GT(j["exposure"].get<double>(), 0);
  // The page loads its data by a script tag (works from file://), nothing else.
  const std::string html = ReadFileToString(view / "index.html");
  EXPECT_NE(html.find("<script src=\"viewer_data.js\"></script>"), std::string::npos);
  EXPECT_EQ(html.find("http://"), std::string::npos);
  EXPECT_EQ(html.find("https://"), std::string::npos);
  EXPECT_EQ(html.find("fetch("), std::string::npos);
  // Written again over itself: an earlier viewer folder is replaced.
  const cli_test::Result again = RunRouen("view " + Q(*root_ / "scene") + " --out " + Q(view) +
                                          " --times 2 --texels-per-cell 2");
  ASSERT_EQ(again.code, 0) << again.out;
  EXPECT_NE(again.out.find("index.html: 2 times"), std::string::npos) << again.out;
  // Put back what the other tests open.
  ASSERT_EQ(RunRouen("view " + Q(*root_ / "scene") + " --out " + Q(view) + " --times " +
                     std::to_string(kTimes))
                .code,
            0);
}

TEST_F(ViewCli, ErrorsNameTheProblemAndWriteNothing) {
  const fs::path other = *root_ / "other";
  fs::create_directories(other);
  WriteFileAtomic(other / "notes.txt", "mine");
  cli_test::Result r = RunRouen("view " + Q(*root_ / "scene") + " --out " + Q(other));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("not a viewer folder"), std::string::npos) << r.out;
  EXPECT_EQ(ReadFileToString(other / "notes.txt"), "mine");
  r = RunRouen("view " + Q(*root_ / "nowhere") + " --out " + Q(*root_ / "v2"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("no such scene folder"), std::string::npos) << r.out;
  r = RunRouen("view " + Q(*root_ / "scene") + " --out " + Q(*root_ / "missing" / "v"));
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.out.find("--out"), std::string::npos) << r.out;
  r = RunRouen("view " + Q(*root_ / "scene") + " --out " + Q(*root_ / "v3") + " --times 1");
  EXPECT_NE(r.code, 0);
  EXPECT_NE(r.out.find("--times"), std::string::npos) << r.out;
  EXPECT_FALSE(fs::exists(*root_ / "v2"));
  EXPECT_FALSE(fs::exists(*root_ / "v3"));
  EXPECT_FALSE(fs::exists(*root_ / "missing"));
  r = RunRouen("view --help");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("Example: rouen view"), std::string::npos) << r.out;
}

double SrgbToLinear(double dn) {
  const double x = dn / 255;
  return x <= 0.04045 ? x / 12.92 : std::pow((x + 0.055) / 1.055, 2.4);
}

// Linear luminance-like mean of a pixel's three 8-bit sRGB values.
double Linear(const Image& img, int x, int y) {
  return (SrgbToLinear(img.at(x, y, 0)) + SrgbToLinear(img.at(x, y, 1)) +
          SrgbToLinear(img.at(x, y, 2))) /
         3;
}

Image RgbOf(const Image& rgba) {
  Image rgb(rgba.width, rgba.height, 3, PixelUnits::kRadiance);
  for (size_t p = 0; p < static_cast<size_t>(rgb.width) * rgb.height; ++p)
    for (int c = 0; c < 3; ++c) rgb.data[p * 3 + c] = rgba.data[p * 4 + c];
  return rgb;
}

struct Render {
  Image rgba;     // radiance and coverage
  Image digital;  // through the page's tone mapping (exposure, sRGB)
};

// Building pixels well inside the silhouette: the render's coverage 1 at the pixel and its
// four neighbours.
std::vector<std::pair<int, int>> Inside(const Image& rgba) {
  std::vector<std::pair<int, int>> px;
  for (int y = 1; y + 1 < rgba.height; ++y)
    for (int x = 1; x + 1 < rgba.width; ++x)
      if (rgba.at(x, y, 3) == 1 && rgba.at(x - 1, y, 3) == 1 && rgba.at(x + 1, y, 3) == 1 &&
          rgba.at(x, y - 1, 3) == 1 && rgba.at(x, y + 1, 3) == 1)
        px.push_back({x, y});
  return px;
}

// Mean absolute difference (digital numbers, over the channels) on the pixels.
double MeanAbsDiff(const Image& a, const Image& b, const std::vector<std::pair<int, int>>& px) {
  double sum = 0;
  for (auto [x, y] : px)
    for (int c = 0; c < 3; ++c) sum += std::abs(a.at(x, y, c) - b.at(x, y, c));
  return sum / (3.0 * px.size());
}

TEST_F(ViewCli, RelightsLikeRouenRenderInHeadlessChromium) {
  const std::optional<std::string> chromium = devtools::FindChromium();
  if (!chromium)
    GTEST_SKIP() << "chromium is not installed (Debian: apt-get install chromium): the viewer "
                    "was not opened in a browser";
  const fs::path build = fs::path(ROUEN_BINARY).parent_path().parent_path();
  const std::string url = "file://" + fs::absolute(*root_ / "view" / "index.html").string();
  std::vector<std::string> errors;
  nlohmann::json info, camera, orbited, zoomed;
  std::map<std::string, Image> shots;
  std::map<std::string, nlohmann::json> states;
  {
    // Software WebGL (SwiftShader through ANGLE): no GPU needed.
    devtools::Browser browser(*chromium, *root_ / "chromium-profile", *root_ / "chromium.log", 120,
                              {"--use-angle=swiftshader", "--enable-unsafe-swiftshader"});
    browser.OpenPage();
    for (const char* domain : {"Page", "Runtime", "Log"})
      browser.Call(std::string(domain) + ".enable");
    browser.Call(
        "Emulation.setDeviceMetricsOverride",
        {{"width", kWidth}, {"height", kHeight}, {"deviceScaleFactor", 1}, {"mobile", false}});
    browser.ClearEvents();
    browser.Call("Page.navigate", {{"url", url}});
    browser.WaitEvent("Page.loadEventFired");
    auto eval = [&](const std::string& expression) {
      const nlohmann::json r = browser.Call(
          "Runtime.evaluate",
          {{"expression", expression}, {"returnByValue", true}, {"awaitPromise", true}});
      if (r.contains("exceptionDetails")) {
        errors.push_back(r["exceptionDetails"].dump());
        return nlohmann::json();
      }
      return r.at("result").value("value", nlohmann::json());
    };
    // The textures loaded and drawn; the WebGL context's renderer.
    info = nlohmann::json::parse(eval(R"(rouenViewer.whenReady.then(r => JSON.stringify({
        renderer: r, times: rouenViewer.data.times, frames: rouenViewer.frames})))")
                                     .get<std::string>());
    // A camera high in the north-east: the east face and the plaza east of the tower take the
    // morning sun, the plaza west of it (in the tower's morning shadow) the evening's.
    camera = nlohmann::json::parse(eval(R"(rouenViewer.setControlsVisible(false);
                rouenViewer.setCamera({eye: [22, 30, 36], target: [-3, -2, 3], fov_x_deg: 60});
                JSON.stringify(rouenViewer.camera()))")
                                       .get<std::string>());
    auto shoot = [&](const std::string& name, const std::string& setup) {
      states[name] = nlohmann::json::parse(
          eval(setup + "; JSON.stringify(rouenViewer.state())").get<std::string>());
      const nlohmann::json shot = browser.Call("Page.captureScreenshot", {{"format", "png"}});
      const fs::path file = build / ("view_screenshot_" + name + ".png");
      WriteFileAtomic(file, devtools::DecodeBase64(shot.at("data").get<std::string>()));
      shots[name] = ReadImage(file.string());
    };
    shoot("morning", "rouenViewer.setOvercast(0); rouenViewer.setBase(1)");
    shoot("evening", "rouenViewer.setBase(" + std::to_string(kTimes - 2) + ")");
    shoot("noon", "rouenViewer.setBase(" + std::to_string(kTimes / 2) + ")");
    shoot("overcast", "rouenViewer.setOvercast(1)");
    shoot("sunrise_auto",
          "rouenViewer.setOvercast(0); rouenViewer.setAutoExposure(true); "
          "rouenViewer.setBase(0)");
    // The mouse orbits: a drag across the canvas turns the camera about its target, keeping
    // the distance; the wheel zooms.
    for (const auto& [type, x] : std::vector<std::pair<std::string, int>>{{"mousePressed", 300},
                                                                          {"mouseMoved", 340},
                                                                          {"mouseMoved", 380},
                                                                          {"mouseReleased", 380}})
      browser.Call("Input.dispatchMouseEvent", {{"type", type},
                                                {"x", x},
                                                {"y", 200},
                                                {"button", "left"},
                                                {"buttons", type == "mouseReleased" ? 0 : 1},
                                                {"clickCount", 1}});
    orbited =
        nlohmann::json::parse(eval("JSON.stringify(rouenViewer.camera())").get<std::string>());
    browser.Call("Input.dispatchMouseEvent",
                 {{"type", "mouseWheel"}, {"x", 300}, {"y", 200}, {"deltaX", 0}, {"deltaY", 200}});
    zoomed = nlohmann::json::parse(eval("JSON.stringify(rouenViewer.camera())").get<std::string>());
    for (const nlohmann::json& e : browser.events()) {
      const std::string m = e.value("method", "");
      const nlohmann::json& p = e.value("params", nlohmann::json::object());
      if (m == "Runtime.exceptionThrown") errors.push_back(p.dump());
      if (m == "Runtime.consoleAPICalled" &&
          (p.value("type", "") == "error" || p.value("type", "") == "assert"))
        errors.push_back(p.dump());
      if (m == "Log.entryAdded" && p["entry"].value("level", "") == "error")
        errors.push_back(p.dump());
    }
  }
  ASSERT_TRUE(errors.empty()) << nlohmann::json(errors).dump(1);
  EXPECT_FALSE(info["renderer"].get<std::string>().empty()) << info.dump();
  ASSERT_EQ(info["times"].size(), static_cast<size_t>(kTimes));
  ASSERT_EQ(camera["width"], kWidth);
  ASSERT_EQ(camera["height"], kHeight);
  auto distance = [](const nlohmann::json& c) {
    double d = 0;
    for (int k = 0; k < 3; ++k) {
      const double e = c["eye"][k].get<double>() - c["target"][k].get<double>();
      d += e * e;
    }
    return std::sqrt(d);
  };
  EXPECT_EQ(orbited["target"], camera["target"]);
  EXPECT_NEAR(distance(orbited), distance(camera), 1e-6);
  EXPECT_GT(std::hypot(orbited["eye"][0].get<double>() - camera["eye"][0].get<double>(),
                       orbited["eye"][1].get<double>() - camera["eye"][1].get<double>()),
            1)
      << "the drag did not turn the camera: " << orbited.dump();
  EXPECT_GT(distance(zoomed), 1.1 * distance(orbited)) << "the wheel did not zoom out";
  for (const auto& [name, img] : shots) {
    ASSERT_EQ(img.width, kWidth) << name;
    ASSERT_EQ(img.height, kHeight) << name;
  }

  // rouen render through the page's camera, at the page's times, tone mapped as the page does.
  auto list = [](const nlohmann::json& v) {
    return FormatNumber(v[0].get<double>()) + "," + FormatNumber(v[1].get<double>()) + "," +
           FormatNumber(v[2].get<double>());
  };
  auto render = [&](const std::string& name, double pbs) {
    const nlohmann::json& st = states.at(name);
    EXPECT_EQ(st["w"].get<double>(), 0) << "the page is not at a basis time: " << st.dump();
    const std::string time = info["times"][st["i0"].get<int>()].get<std::string>();
    const fs::path exr = *root_ / ("render_" + name + ".exr");
    const cli_test::Result r = RunRouen(
        "render " + Q(*root_ / "scene") + " --time " + time + " --look-at " +
        list(camera["target"]) + " --from-point " + list(camera["eye"]) + " --fov " +
        FormatNumber(camera["fov_x_deg"].get<double>()) + " --size " + std::to_string(kWidth) +
        "x" + std::to_string(kHeight) + " --pbs " + FormatNumber(pbs) + " --out " + Q(exr));
    EXPECT_EQ(r.code, 0) << r.out;
    Render out;
    out.rgba = ReadImage(exr.string(), true);
    out.digital = ToSrgbDigital(RgbOf(out.rgba), st["exposure"].get<double>());
    WriteImage((build / ("view_render_" + name + ".png")).string(), out.digital,
               StoredType::kUint8);
    return out;
  };
  const Render morning = render("morning", 0), evening = render("evening", 0),
               overcast = render("overcast", 1), noon = render("noon", 0);
  ASSERT_EQ(morning.rgba.channels, 4);
  ASSERT_EQ(morning.rgba.width, kWidth);

  // The page's images match rouen render's of the same camera, time and exposure on the
  // building, and each is far from the other time's.
  const std::vector<std::pair<int, int>> inside = Inside(morning.rgba);
  ASSERT_GT(inside.size(), static_cast<size_t>(kWidth * kHeight / 20));
  const double mm = MeanAbsDiff(shots["morning"], morning.digital, inside);
  const double me = MeanAbsDiff(shots["morning"], evening.digital, inside);
  const double ee = MeanAbsDiff(shots["evening"], evening.digital, inside);
  const double em = MeanAbsDiff(shots["evening"], morning.digital, inside);
  const double oo = MeanAbsDiff(shots["overcast"], overcast.digital, inside);
  const double nn = MeanAbsDiff(shots["noon"], noon.digital, inside);
  std::printf(
      "mean |page - render| (DN): morning %.2f (vs the evening render %.2f), evening %.2f "
      "(%.2f), noon %.2f, overcast %.2f\n",
      mm, me, ee, em, nn, oo);
  EXPECT_LT(mm, 4);
  EXPECT_LT(ee, 4);
  EXPECT_LT(nn, 4);
  EXPECT_LT(oo, 4);
  EXPECT_LT(mm, 0.5 * me);
  EXPECT_LT(ee, 0.5 * em);

  // Sunlit and shaded parts swap: where rouen's morning render is twice as bright as its
  // evening one (the east face, the evening shadow), the page's morning screenshot is brighter
  // than its evening one, and the other way round (the morning shadow).
  std::vector<std::pair<int, int>> am, pm;
  for (auto [x, y] : inside) {
    const double lm = morning.rgba.at(x, y, 1), le = evening.rgba.at(x, y, 1);
    if (lm > 2 * le) am.push_back({x, y});
    if (le > 2 * lm) pm.push_back({x, y});
  }
  ASSERT_GT(am.size(), inside.size() / 40) << "nothing lit in the morning only";
  ASSERT_GT(pm.size(), inside.size() / 40) << "nothing lit in the evening only";
  auto mean = [](const Image& img, const std::vector<std::pair<int, int>>& px) {
    double s = 0;
    for (auto [x, y] : px) s += Linear(img, x, y);
    return s / px.size();
  };
  std::printf(
      "lit in the morning only (%zu px): page %.3f -> %.3f; in the evening only (%zu px): "
      "%.3f -> %.3f\n",
      am.size(), mean(shots["morning"], am), mean(shots["evening"], am), pm.size(),
      mean(shots["morning"], pm), mean(shots["evening"], pm));
  EXPECT_GT(mean(shots["morning"], am), 2 * mean(shots["evening"], am));
  EXPECT_GT(mean(shots["evening"], pm), 2 * mean(shots["morning"], pm));

  // Overcast lowers the contrast: the parts the sun lights most at noon (the quarter of the
  // building's pixels where rouen's clear render is brightest relative to its overcast one)
  // against those it lights least, in the page's clear and overcast screenshots.
  std::vector<std::pair<double, std::pair<int, int>>> by_sun;
  for (auto [x, y] : inside)
    by_sun.push_back({noon.rgba.at(x, y, 1) / std::max(1e-9f, overcast.rgba.at(x, y, 1)), {x, y}});
  std::sort(by_sun.begin(), by_sun.end());
  std::vector<std::pair<int, int>> least, most;
  for (size_t i = 0; i < by_sun.size() / 4; ++i) {
    least.push_back(by_sun[i].second);
    most.push_back(by_sun[by_sun.size() - 1 - i].second);
  }
  const double contrast_clear = mean(shots["noon"], most) / mean(shots["noon"], least);
  const double contrast_overcast = mean(shots["overcast"], most) / mean(shots["overcast"], least);
  std::printf("sunlit / shaded brightness: clear %.3f, overcast %.3f\n", contrast_clear,
              contrast_overcast);
  // Each time's own exposure: at sunrise (the sun 1 degree high; this scene's one slot gives no
  // extinction, so the low sun is as strong and lights the east face head-on) the page takes
  // the exposure `rouen view` computed for that time (viewer_data.js, bases[0]), not the day's
  // (noon's), and looks as rouen render at that exposure.
  const std::string js = ReadFileToString(*root_ / "view" / "viewer_data.js");
  const nlohmann::json data =
      nlohmann::json::parse(js.substr(js.find('=') + 1, js.rfind(';') - js.find('=') - 1));
  const double own = data["bases"][0]["exposure"].get<double>();
  const double day = data["exposure"].get<double>();
  std::printf("exposure at sunrise %.5g, the day's %.5g\n", own, day);
  ASSERT_NE(own, day);
  EXPECT_NEAR(states["sunrise_auto"]["exposure"].get<double>() / own, 1, 1e-6);
  EXPECT_NEAR(states["noon"]["exposure"].get<double>() / day, 1, 1e-6);
  const Render sunrise = render("sunrise_auto", 0);
  EXPECT_LT(MeanAbsDiff(shots["sunrise_auto"], sunrise.digital, inside), 4);
  // Overcast lowers the contrast between those parts (the two sets face differently, so the
  // overcast sky need not light them alike: only less unlike than the sun does).
  EXPECT_GT(contrast_clear, 1.2);
  EXPECT_LT(std::abs(std::log(contrast_overcast)), std::abs(std::log(contrast_clear)));
}

// A scene with a camera response: the page tone maps through it by default, as rouen render
// --png does (ToDigital at the page's exposure factor).
TEST_F(ViewCli, TonemapsThroughTheScenesResponse) {
  const std::optional<std::string> chromium = devtools::FindChromium();
  if (!chromium)
    GTEST_SKIP() << "chromium is not installed (Debian: apt-get install chromium): the viewer "
                    "was not opened in a browser";
  const fs::path scene = *root_ / "response.scene";
  fs::remove_all(scene);
  fs::copy(*root_ / "scene", scene, fs::copy_options::recursive);
  ResponseCurve response;
  for (int c = 0; c < 3; ++c)
    for (int z = 0; z < 256; ++z)  // a gamma-like camera, each channel its own
      response.g[c].push_back((2.0 + 0.2 * c) * std::log((z + 1.0) / 256));
  nlohmann::json j = nlohmann::json::parse(ReadFileToString(scene / "scene.json"));
  j["response"] = response;
  WriteFileAtomic(scene / "scene.json", j.dump(1));
  const fs::path view = *root_ / "response.view";
  const cli_test::Result r =
      RunRouen("view " + Q(scene) + " --out " + Q(view) + " --times " + std::to_string(kTimes));
  ASSERT_EQ(r.code, 0) << r.out;
  std::vector<std::string> errors;
  nlohmann::json camera, state;
  Image shot;
  const fs::path build = fs::path(ROUEN_BINARY).parent_path().parent_path();
  {
    devtools::Browser browser(*chromium, *root_ / "chromium-profile-2", *root_ / "chromium-2.log",
                              120, {"--use-angle=swiftshader", "--enable-unsafe-swiftshader"});
    browser.OpenPage();
    for (const char* domain : {"Page", "Runtime", "Log"})
      browser.Call(std::string(domain) + ".enable");
    browser.Call(
        "Emulation.setDeviceMetricsOverride",
        {{"width", kWidth}, {"height", kHeight}, {"deviceScaleFactor", 1}, {"mobile", false}});
    browser.Call("Page.navigate",
                 {{"url", "file://" + fs::absolute(view / "index.html").string() + "#controls=0"}});
    browser.WaitEvent("Page.loadEventFired");
    const nlohmann::json e =
        browser.Call("Runtime.evaluate", {{"expression", R"(rouenViewer.whenReady.then(() => {
            rouenViewer.setCamera({eye: [22, 30, 36], target: [-3, -2, 3], fov_x_deg: 60});
            rouenViewer.setBase(1);
            return JSON.stringify({camera: rouenViewer.camera(), state: rouenViewer.state()}); }))"},
                                          {"returnByValue", true},
                                          {"awaitPromise", true}});
    ASSERT_FALSE(e.contains("exceptionDetails")) << e.dump();
    const nlohmann::json v = nlohmann::json::parse(e["result"]["value"].get<std::string>());
    camera = v["camera"];
    state = v["state"];
    const nlohmann::json png = browser.Call("Page.captureScreenshot", {{"format", "png"}});
    WriteFileAtomic(build / "view_screenshot_response.png",
                    devtools::DecodeBase64(png.at("data").get<std::string>()));
    shot = ReadImage((build / "view_screenshot_response.png").string());
    for (const nlohmann::json& ev : browser.events()) {
      const std::string m = ev.value("method", "");
      const nlohmann::json& p = ev.value("params", nlohmann::json::object());
      if (m == "Runtime.exceptionThrown" ||
          (m == "Runtime.consoleAPICalled" && p.value("type", "") == "error") ||
          (m == "Log.entryAdded" && p["entry"].value("level", "") == "error"))
        errors.push_back(p.dump());
    }
  }
  ASSERT_TRUE(errors.empty()) << nlohmann::json(errors).dump(1);
  EXPECT_EQ(state["tone"], "response");
  auto list = [](const nlohmann::json& v) {
    return FormatNumber(v[0].get<double>()) + "," + FormatNumber(v[1].get<double>()) + "," +
           FormatNumber(v[2].get<double>());
  };
  const std::string js = ReadFileToString(view / "viewer_data.js");
  const nlohmann::json data =
      nlohmann::json::parse(js.substr(js.find('=') + 1, js.rfind(';') - js.find('=') - 1));
  const fs::path exr = *root_ / "render_response.exr";
  const cli_test::Result rr =
      RunRouen("render " + Q(scene) + " --time " + data["bases"][1]["utc"].get<std::string>() +
               " --look-at " + list(camera["target"]) + " --from-point " + list(camera["eye"]) +
               " --fov " + FormatNumber(camera["fov_x_deg"].get<double>()) + " --size " +
               std::to_string(kWidth) + "x" + std::to_string(kHeight) + " --out " + Q(exr));
  ASSERT_EQ(rr.code, 0) << rr.out;
  const Image rgba = ReadImage(exr.string(), true);
  const Image expect = ToDigital(RgbOf(rgba), response, state["exposure"].get<double>());
  WriteImage((build / "view_render_response.png").string(), expect, StoredType::kUint8);
  const std::vector<std::pair<int, int>> inside = Inside(rgba);
  ASSERT_GT(inside.size(), static_cast<size_t>(kWidth * kHeight / 20));
  const double through = MeanAbsDiff(shot, expect, inside);
  const double srgb =
      MeanAbsDiff(shot, ToSrgbDigital(RgbOf(rgba), state["exposure"].get<double>()), inside);
  std::printf("mean |page - render| through the response: %.2f DN (sRGB instead: %.2f DN)\n",
              through, srgb);
  EXPECT_LT(through, 4);
  EXPECT_LT(through, 0.5 * srgb);
}

}  // namespace
}  // namespace rouen
