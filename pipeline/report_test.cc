#include "pipeline/report.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/files.h"
#include "core/image.h"
#include "core/solar.h"
#include "solve/scene.h"
#include "solve/test_scenes.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

const char* kSections[] = {"overview",    "sky",    "timeline",   "sunpath", "response",
                           "environment", "albedo", "validation", "timings"};

int Count(const std::string& text, const std::string& what) {
  int n = 0;
  for (size_t p = text.find(what); p != std::string::npos; p = text.find(what, p + 1)) ++n;
  return n;
}

// The absent notes of section `id`, joined.
std::string AbsentOf(const ReportSummary& s, const std::string& id) {
  std::string out;
  for (const ReportSection& sec : s.sections)
    if (sec.id == id)
      for (const std::string& a : sec.absent) out += a + "\n";
  return out;
}

// A small solved scene written by WriteScene: a plaza and a tower (one block name with markup
// characters), three slots with a sky and a constant environment each, the second held out;
// no response curve (HDR photos) and no timings.
class ReportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("rouen_report_test_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    scene_ = dir_ / "scene";
    Mesh mesh;
    const int plaza = mesh.AddBlock("plaza");
    const int tower = mesh.AddBlock("tower<1>&");
    testing::AddHorizontalRect(&mesh, -10, 10, -10, 10, 0, true, plaza);
    testing::AddBox(&mesh, {-2, -2, 0}, {2, 2, 12}, tower);
    SceneModel s;
    s.site = Site{37.87, -122.26, 60};
    s.grid_options.spacing_m = 1.0;
    s.model_file = "model.obj";
    const SurfaceGrid grid = BuildSurfaceGrid(mesh, s.grid_options);
    for (const char* t : {"2026-08-25T16:00:00Z", "2026-08-25T19:30:00Z", "2026-08-25T23:00:00Z"}) {
      SlotModel slot;
      slot.utc = ParseIso8601(t);
      const SunPosition sun = ComputeSunPosition(slot.utc, s.site);
      slot.sun_dir = sun.DirectionEnu();
      slot.sun_radiance = Eigen::Vector3d(1.5e4, 1.4e4, 1.2e4);
      slot.sun_solid_angle_sr = sun.SolidAngleSr();
      for (SkyParams& p : slot.sky.channel) p = SkyParams{1, -1, -0.3, 10, -3, 0.45, 1};
      slot.sky.sun_dir = slot.sun_dir;
      slot.env = EnvironmentMap::Constant(EnvOptions(), {1, 2, 3}, {0.5, 0.4, 0.3});
      s.slots.push_back(slot);
    }
    for (int i = 0; i < grid.size(); ++i) {
      s.albedo.rho_sun.emplace_back(0.2, 0.3, 0.4);
      s.albedo.rho_se.emplace_back(0.25, 0.3, 0.35);
      s.albedo.observations.push_back(i % 4);
      s.albedo.flags.push_back(i % 3 == 0 ? kAlbedoSunUnobserved
                                          : (i % 3 == 1 ? kAlbedoNeverShadowed : 0));
    }
    s.albedo.retro = {0.0, 0.5};
    s.albedo.summary.points = grid.size();
    s.holdout_slots = {1};
    s.inputs_sha256 = std::string(64, 'a');
    s.rouen_version = "0.0.1";
    WriteScene(scene_, s, &mesh);
    request_.scene = scene_;
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Edits scene.json.
  void EditJson(const std::function<void(nlohmann::json&)>& edit) {
    nlohmann::json j = nlohmann::json::parse(ReadFileToString(scene_ / "scene.json"));
    edit(j);
    WriteFileAtomic(scene_ / "scene.json", j.dump(1));
  }

  fs::path dir_, scene_;
  ReportRequest request_;
};

TEST_F(ReportTest, EverySectionIsThereAndSaysWhatIsMissing) {
  ReportSummary summary;
  const std::string html = BuildReport(request_, &summary);
  ASSERT_EQ(summary.sections.size(), 9u);
  for (const char* id : kSections)
    EXPECT_NE(html.find("<section id=\"" + std::string(id) + "\">"), std::string::npos) << id;
  // No section failed: every absence is one the scene explains.
  EXPECT_EQ(html.find("could not be completed"), std::string::npos) << html.substr(0, 2000);
  EXPECT_NE(AbsentOf(summary, "timeline").find("No session given"), std::string::npos);
  EXPECT_NE(AbsentOf(summary, "response").find("no response curve"), std::string::npos);
  EXPECT_NE(AbsentOf(summary, "sky").find("--work"), std::string::npos);
  EXPECT_NE(AbsentOf(summary, "validation").find("No validation results"), std::string::npos);
  EXPECT_NE(AbsentOf(summary, "timings").find("no timings"), std::string::npos);
  EXPECT_EQ(AbsentOf(summary, "sunpath"), "");
  EXPECT_EQ(AbsentOf(summary, "albedo"), "");
  EXPECT_EQ(AbsentOf(summary, "environment"), "");
  // Sun chart: the path, the captured slots and the held-out one; two sky-model plots of 3.
  EXPECT_GE(summary.plots, 3);
  EXPECT_EQ(Count(html, "data-label=\"held-out slots\""), 1);
  EXPECT_EQ(Count(html, "data-label=\"slot 2 23:00\""), 2);
  // Three slots of environment maps, two images of normals; per block 3 atlas images.
  EXPECT_EQ(summary.images, 3 + 2 + 2 * 3);
  EXPECT_EQ(Count(html, "<img src=\"data:image/png;base64,"), summary.images);
  // The block name is text, escaped wherever it appears.
  EXPECT_EQ(html.find("tower<1>"), std::string::npos);
  EXPECT_NE(html.find("tower&lt;1&gt;&amp;"), std::string::npos);
  EXPECT_EQ(html.find("<script"), std::string::npos);
  EXPECT_EQ(summary.bytes, html.size());
}

TEST_F(ReportTest, MissingOptionalFilesAreSaidNotFatal) {
  fs::remove_all(scene_ / "atlas");
  fs::remove(scene_ / "normals.exr");
  fs::remove(scene_ / "points.exr");
  EditJson([](nlohmann::json& j) {
    j["timings"] = nullptr;
    j.erase("provenance");
    j.erase("environment");
  });
  ReportSummary summary;
  const std::string html = BuildReport(request_, &summary);
  EXPECT_EQ(summary.sections.size(), 9u);
  // The atlases are baked from the albedo grids instead, and the page says so.
  const std::string albedo = AbsentOf(summary, "albedo");
  EXPECT_NE(albedo.find("baked from the albedo grids"), std::string::npos) << albedo;
  EXPECT_NE(albedo.find("is missing"), std::string::npos) << albedo;
  EXPECT_EQ(Count(html, "(baked from the albedo grids)</h3>"), 2);
  EXPECT_EQ(summary.images, 3 + 2 + 2 * 3);
}

TEST_F(ReportTest, UnreadableAlbedosLeaveTheOtherSections) {
  fs::remove(scene_ / "albedo_sun.exr");
  ReportSummary summary;
  const std::string html = BuildReport(request_, &summary);
  EXPECT_EQ(summary.sections.size(), 9u);
  EXPECT_NE(AbsentOf(summary, "albedo").find("albedo_sun.exr"), std::string::npos);
  EXPECT_EQ(AbsentOf(summary, "sunpath"), "");
  EXPECT_NE(html.find("data-label=\"captured slots\""), std::string::npos);
}

TEST_F(ReportTest, BrokenSlotsAreSaidInTheSectionsThatNeedThem) {
  EditJson([](nlohmann::json& j) { j["slots"][1]["sky"] = "not a sky"; });
  ReportSummary summary;
  BuildReport(request_, &summary);
  for (const char* id : {"sunpath", "sky", "environment"})
    EXPECT_NE(AbsentOf(summary, id).find("slots cannot be read"), std::string::npos) << id;
}

TEST_F(ReportTest, TimingsMetricsAndValidationAreShownWhenGiven) {
  EditJson([](nlohmann::json& j) {
    j["timings"] = {{{"stage", "response curve"}, {"seconds", 1.5}},
                    {{"stage", "albedo <fit>"}, {"seconds", 12.25}}};
  });
  WriteFileAtomic(dir_ / "v.json",
                  R"({"slot": 1, "measured": {"rel_rmse": 0.0379, "psnr_db": 36.7},
                      "photos": [{"view": "slot1/architecture/view0",
                                  "measured": {"rel_rmse": 0.041}}]})");
  request_.metrics = {dir_ / "v.json"};
  Validation v;
  v.slot = 1;
  v.held_out = true;
  PhotoValidation p;
  p.view = "slot1/architecture/view0";
  p.photo = Image(8, 6, 3, PixelUnits::kRadiance, 2.f);
  p.rendered_measured = Image(8, 6, 3, PixelUnits::kRadiance, 2.2f);
  p.rendered_predicted = Image(8, 6, 3, PixelUnits::kRadiance, 1.8f);
  p.mask.assign(48, 1);
  p.measured.rel_rmse = 0.1;
  p.predicted = RenderMetrics{};
  v.photos = {p};
  v.predicted = RenderMetrics{};
  request_.validation = &v;
  ReportSummary summary;
  const std::string html = BuildReport(request_, &summary);
  EXPECT_EQ(AbsentOf(summary, "timings"), "");
  EXPECT_EQ(AbsentOf(summary, "validation"), "");
  EXPECT_NE(html.find("albedo &lt;fit&gt;"), std::string::npos);
  EXPECT_NE(html.find("<td class=\"n\">13.75</td>"), std::string::npos);  // the total
  EXPECT_NE(html.find("photos[slot1/architecture/view0].measured.rel_rmse"), std::string::npos);
  EXPECT_NE(html.find("<td class=\"n\">0.0379</td>"), std::string::npos);
  // Photo, two renders, two error maps.
  EXPECT_EQ(summary.images, 3 + 2 + 2 * 3 + 5);
}

TEST_F(ReportTest, ASceneFolderWithoutSceneJsonIsAnError) {
  fs::remove(scene_ / "scene.json");
  try {
    BuildReport(request_);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find((scene_ / "scene.json").string()), std::string::npos)
        << e.what();
  }
  WriteFileAtomic(scene_ / "scene.json", "[1, 2");
  EXPECT_THROW(BuildReport(request_), Error);
  request_.scene = dir_ / "nowhere";
  EXPECT_THROW(BuildReport(request_), Error);
}

TEST_F(ReportTest, WriteReportWritesThePageWhole) {
  const ReportSummary s = WriteReport(request_, dir_ / "report.html");
  EXPECT_EQ(fs::file_size(dir_ / "report.html"), s.bytes);
  EXPECT_THROW(WriteReport(request_, dir_ / "no such folder" / "report.html"), Error);
  EXPECT_FALSE(fs::exists(dir_ / "no such folder"));
}

}  // namespace
}  // namespace rouen
