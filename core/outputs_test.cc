#include "core/outputs.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <iterator>
#include <string>

#include "core/error.h"
#include "core/error_of.h"
#include "core/files.h"
#include "core/image.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

class OutputsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("rouen_outputs_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  int Entries() const {
    return static_cast<int>(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()));
  }
  fs::path dir_;
};

TEST_F(OutputsTest, AllOrNothing) {
  const std::string a = (dir_ / "a.exr").string(), b = (dir_ / "b.json").string();
  {
    OutputSet out;
    const std::string ta = out.Add("--out", a, OutputKind::kRadiance);
    const std::string tb = out.Add("--summary", b, OutputKind::kFile);
    EXPECT_NE(ta.find(".tmp-"), std::string::npos);
    EXPECT_EQ(fs::path(ta).extension(), ".exr");  // writers choose the format by extension
    WriteImage(ta, Image(2, 1, 3, PixelUnits::kRadiance, 1.5f), StoredType::kFloat);
    // The second output is never written: an error before Commit.
  }
  EXPECT_EQ(Entries(), 0) << "a failed command leaves neither outputs nor temporaries";
  OutputSet out;
  WriteImage(out.Add("--out", a, OutputKind::kRadiance),
             Image(2, 1, 3, PixelUnits::kRadiance, 1.5f), StoredType::kFloat);
  WriteFileAtomic(out.Add("--summary", b, OutputKind::kFile), "{}\n");
  EXPECT_FALSE(fs::exists(a));
  out.Commit();
  EXPECT_EQ(ReadImage(a).data[0], 1.5f);
  EXPECT_EQ(ReadFileToString(b), "{}\n");
  EXPECT_EQ(Entries(), 2);
}

TEST_F(OutputsTest, RefusesBeforeAnyWorkNamingTheOption) {
  OutputSet out;
  EXPECT_EQ(ErrorOf([&] { out.Add("--out", dir_.string(), OutputKind::kRadiance); }),
            "--out " + dir_.string() + ": is a folder; give a file name (e.g. " +
                (dir_ / "out.exr").string() + ")");
  EXPECT_EQ(ErrorOf([&] { out.Add("--out", (dir_ / "x.png").string(), OutputKind::kRadiance); }),
            "--out " + (dir_ / "x.png").string() +
                ": radiance needs a floating-point image format (.exr, .hdr, .pfm or .tif), not "
                "'.png'");
  EXPECT_NE(ErrorOf([&] {
              out.Add("--out", (dir_ / "no/x.exr").string(), OutputKind::kRadiance);
            }).find("no such folder " + (dir_ / "no").string()),
            std::string::npos);
  WriteFileAtomic(dir_ / "file", "x");
  EXPECT_NE(ErrorOf([&] {
              out.Add("--out", (dir_ / "file/x.exr").string(), OutputKind::kFile);
            }).find("is not a folder"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] {
              out.Add("--png", (dir_ / "x.nosuchformat").string(), OutputKind::kImage);
            }).find("no image format"),
            std::string::npos);
  EXPECT_EQ(ErrorOf([&] { out.Add("--out", "", OutputKind::kFile); }), "--out: no file name given");
  out.Add("--out", (dir_ / "same.exr").string(), OutputKind::kRadiance);
  EXPECT_NE(ErrorOf([&] {
              out.Add("--coverage", (dir_ / "." / "same.exr").string(), OutputKind::kRadiance);
            }).find("the same file as --out"),
            std::string::npos);
  EXPECT_EQ(Entries(), 2);  // "file" and the reserved temporary of same.exr
}

// An output never replaces what the command reads: a protected file, or a file inside a
// protected folder (a scene, a session), whichever is declared first; nor a device or a pipe,
// which renaming the finished temporary over would turn into a regular file.
TEST_F(OutputsTest, OutputsNeverReplaceInputsDevicesOrPipes) {
  const fs::path scene = dir_ / "scene";
  fs::create_directories(scene / "sub");
  WriteFileAtomic(scene / "scene.json", "{}");
  WriteFileAtomic(dir_ / "list.txt", "a.jpg 1\n");
  {
    OutputSet out;
    out.Protect("the scene", scene.string());
    out.Protect("--list", (dir_ / "list.txt").string());
    out.Protect("--session", "");  // not given: nothing
    for (const fs::path& p :
         {scene / "scene.json", scene / "sub" / "new.json", scene / "sub" / ".." / "scene.json"}) {
      EXPECT_EQ(ErrorOf([&] { out.Add("--out", p.string(), OutputKind::kFile); }),
                "--out " + p.string() + ": would overwrite the scene " + scene.string() +
                    ", an input of this command; write it elsewhere");
    }
    EXPECT_NE(ErrorOf([&] {
                out.Add("--out", (dir_ / "list.txt").string(), OutputKind::kFile);
              }).find("would overwrite --list"),
              std::string::npos);
    // Beside the scene (a name that only begins like it) is fine.
    EXPECT_EQ(
        ErrorOf([&] { out.Add("--out", (dir_ / "scene2.json").string(), OutputKind::kFile); }), "");
  }
  {
    OutputSet out;  // the output declared first, the input after
    const fs::path photos = dir_ / "photos";
    fs::create_directories(photos);
    out.Add("--out", (photos / "report.html").string(), OutputKind::kFile);
    EXPECT_NE(ErrorOf([&] { out.Protect("--photos", photos.string()); }).find("would overwrite"),
              std::string::npos);
  }
  EXPECT_EQ(ReadFileToString(scene / "scene.json"), "{}");
  EXPECT_FALSE(fs::exists(dir_ / "photos" / "report.html"));
  OutputSet out;
  EXPECT_EQ(ErrorOf([&] { out.Add("--out", "/dev/null", OutputKind::kFile); }),
            "--out /dev/null: is not a regular file (a device or a pipe), which the output would "
            "replace; give a file name");
  const fs::path fifo = dir_ / "pipe.json";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_NE(ErrorOf([&] {
              out.Add("--out", fifo.string(), OutputKind::kFile);
            }).find("is not a regular file"),
            std::string::npos);
  EXPECT_TRUE(fs::is_fifo(fifo));
}

// A session or a scene is written only by the commands that make it: an output inside one is
// refused though the command was not told of it (render --png SESSION/frames/000013.png).
TEST_F(OutputsTest, NoOutputLandsInASessionOrASceneItDidNotMake) {
  const fs::path session = dir_ / "s", scene = dir_ / "sc";
  fs::create_directories(session / "frames");
  fs::create_directories(scene / "atlas");
  WriteFileAtomic(session / "session.json", "{}");
  WriteFileAtomic(session / "frames" / "000013.png", "photo");
  WriteFileAtomic(scene / "scene.json", "{}");
  OutputSet out;
  const fs::path photo = session / "frames" / "000013.png";
  EXPECT_EQ(ErrorOf([&] { out.Add("--png", photo.string(), OutputKind::kImage); }),
            "--png " + photo.string() + ": lies inside the session " + session.string() +
                " (it holds session.json), which only capture, import and calib write; write it "
                "elsewhere");
  const fs::path atlas = scene / "atlas" / "roof.exr";
  EXPECT_EQ(ErrorOf([&] { out.Add("--out", atlas.string(), OutputKind::kRadiance); }),
            "--out " + atlas.string() + ": lies inside the scene " + scene.string() +
                " (it holds scene.json), which only rouen solve writes; write it elsewhere");
  // A folder with only a journal is a session too (session.json lost in a crash).
  fs::remove(session / "session.json");
  WriteFileAtomic(session / "frames.jsonl", "");
  EXPECT_NE(ErrorOf([&] {
              out.Add("--out", (session / "new.json").string(), OutputKind::kFile);
            }).find("lies inside the session"),
            std::string::npos);
  EXPECT_EQ(ReadFileToString(photo), "photo");
  EXPECT_EQ(ErrorOf([&] { out.Add("--out", (dir_ / "s.json").string(), OutputKind::kFile); }), "");
  // A folder of outputs is refused before it is made; beside them it is made.
  EXPECT_NE(ErrorOf([&] {
              out.CreateFolder("--images", (scene / "img" / "a").string());
            }).find("lies inside the scene"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(scene / "img"));
  OutputSet protecting;
  protecting.Protect("--photos", (dir_ / "photos").string());
  fs::create_directories(dir_ / "photos");
  EXPECT_NE(ErrorOf([&] {
              protecting.CreateFolder("--out", (dir_ / "photos" / "r").string());
            }).find("would overwrite --photos"),
            std::string::npos);
  EXPECT_FALSE(fs::exists(dir_ / "photos" / "r"));
  EXPECT_EQ(ErrorOf([&] { out.CreateFolder("--images", (dir_ / "img" / "a").string()); }), "");
  EXPECT_TRUE(fs::is_directory(dir_ / "img" / "a"));
  std::string kind;
  EXPECT_EQ(EnclosingSessionOrScene(scene / "atlas" / "x.exr", &kind), scene.string());
  EXPECT_EQ(kind, "scene");
  EXPECT_EQ(EnclosingSessionOrScene(dir_ / "img", &kind), "");
}

TEST_F(OutputsTest, CommitRefusesAnOutputNeverWritten) {
  OutputSet out;
  out.Add("--out", (dir_ / "a.json").string(), OutputKind::kFile);
  EXPECT_NE(ErrorOf([&] {
              out.Commit();
            }).find("--out " + (dir_ / "a.json").string() + ": nothing was written"),
            std::string::npos);
}

TEST_F(OutputsTest, WorkingFoldersMustBeFoldersWeCanWriteIn) {
  EXPECT_EQ(ErrorOf([&] { CheckWritableFolder("--work", dir_.string()); }), "");
  EXPECT_EQ(ErrorOf([&] { CheckWritableFolder("--work", (dir_ / "new" / "deeper").string()); }),
            "");
  EXPECT_FALSE(fs::exists(dir_ / "new")) << "checking creates nothing";
  WriteFileAtomic(dir_ / "file", "x");
  EXPECT_EQ(ErrorOf([&] { CheckWritableFolder("--work", (dir_ / "file").string()); }),
            "--work " + (dir_ / "file").string() + ": is not a folder");
  EXPECT_EQ(ErrorOf([&] { CheckWritableFolder("--work", (dir_ / "file" / "sub").string()); }),
            "--work " + (dir_ / "file" / "sub").string() + ": " + (dir_ / "file").string() +
                " is not a folder");
}

TEST(FloatFormatsTest, WriteImageRefusesToClipRadianceIntoPng) {
  EXPECT_TRUE(IsFloatImageFormat("a.EXR"));
  EXPECT_TRUE(IsFloatImageFormat("dir.png/a.hdr"));
  EXPECT_FALSE(IsFloatImageFormat("a.png"));
  EXPECT_FALSE(IsFloatImageFormat("a"));
  const fs::path p =
      fs::temp_directory_path() / ("rouen_float_" + std::to_string(::getpid()) + ".png");
  EXPECT_THROW(
      WriteImage(p.string(), Image(2, 1, 3, PixelUnits::kRadiance, 1000.f), StoredType::kFloat),
      Error);
  EXPECT_FALSE(fs::exists(p));
}

}  // namespace
}  // namespace rouen
