#include "pipeline/scene.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <string>

#include "core/error.h"
#include "core/error_of.h"
#include "core/files.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

class SceneStageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("rouen_scene_stage_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

TEST_F(SceneStageTest, ASceneIsWrittenOnlyWhereNothingElseIsLost) {
  // A new folder, or an earlier scene, may become the scene.
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "new.scene"); }), "");
  fs::create_directories(dir_ / "old.scene");
  WriteFileAtomic(dir_ / "old.scene" / "scene.json", "{}");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "old.scene"); }), "");
  fs::create_directories(dir_ / "empty");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "empty"); }), "");
  // A folder holding something else, a file, or a folder that does not exist is refused,
  // naming it.
  fs::create_directories(dir_ / "photos");
  WriteFileAtomic(dir_ / "photos" / "a.jpg", "jpeg");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "photos"); }),
            (dir_ / "photos").string() +
                ": exists and is not a scene folder (no scene.json); give a new folder");
  WriteFileAtomic(dir_ / "file", "x");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "file"); }),
            (dir_ / "file").string() + ": exists and is not a folder");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "missing" / "s.scene"); }),
            (dir_ / "missing" / "s.scene").string() + ": the folder " +
                (dir_ / "missing").string() + " does not exist");
}

// A scene never lands inside its session (every solve would then read its own outputs), nor
// around it, nor over another session's scene.
TEST_F(SceneStageTest, ASceneIsNeverWrittenIntoASessionOrOverAnotherSessionsScene) {
  const fs::path session = dir_ / "s", other = dir_ / "t";
  fs::create_directories(session / "frames");
  fs::create_directories(other);
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "s.scene", session); }), "");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(session / "scene", session); }),
            (session / "scene").string() + ": lies inside the session " + session.string() +
                ", whose files the solve reads; write the scene beside the session");
  // Spelled another way, through a link to the session.
  fs::create_symlink(session, dir_ / "link");
  EXPECT_NE(ErrorOf([&] { CheckSceneOutput(dir_ / "link" / "frames" / "x", session); }), "");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_, session); }),
            dir_.string() + ": holds the session " + session.string() +
                "; write the scene beside the session");
  // An earlier scene of this session is replaced; one of another session is not.
  fs::create_directories(dir_ / "t.scene");
  WriteFileAtomic(dir_ / "t.scene" / "scene.json",
                  "{\"provenance\": {\"session\": \"" + other.string() + "\"}}");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "t.scene", other); }), "");
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "t.scene", session); }),
            (dir_ / "t.scene").string() + ": is the scene of another session (" + other.string() +
                "); give a new folder, or remove it first");
  // That session gone (moved or deleted), the scene may be replaced.
  fs::remove_all(other);
  EXPECT_EQ(ErrorOf([&] { CheckSceneOutput(dir_ / "t.scene", session); }), "");
  // The working folder neither, checked before the session is read.
  SolveFolderRequest request;
  request.session = session;
  request.out = dir_ / "s.scene";
  request.work = session / "work";
  EXPECT_EQ(ErrorOf([&] { SolveSessionFolder(request); }),
            "--work " + (session / "work").string() + ": lies inside the session " +
                session.string() + ", whose files the solve reads; give a folder beside it");
}

TEST_F(SceneStageTest, LoadingSomethingThatIsNotASceneSaysSo) {
  EXPECT_EQ(ErrorOf([&] { LoadScene(dir_ / "none"); }),
            (dir_ / "none").string() + ": no such scene folder (rouen solve writes one)");
  WriteFileAtomic(dir_ / "scene.json", "{\"format_version\": 1");
  const std::string m = ErrorOf([&] { LoadScene(dir_); });
  EXPECT_EQ(m.rfind((dir_ / "scene.json").string() + ": not valid JSON", 0), 0u) << m;
}

}  // namespace
}  // namespace rouen
