#include "core/files.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <fstream>
#include <string>

#include "core/error.h"
#include "core/fault_io.h"
#include "core/image.h"

namespace fs = std::filesystem;

namespace rouen {
namespace {

fs::path TempDir(const std::string& name) {
  const fs::path d =
      fs::temp_directory_path() / ("rouen_core_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

TEST(Sha256Test, Fips180Vectors) {
  EXPECT_EQ(Sha256Hex(""), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
  EXPECT_EQ(Sha256Hex("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_EQ(Sha256Hex("abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq"),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(Sha256Hex("abcdefghbcdefghicdefghijdefghijkefghijklfghijklmghijklmnhijklmno"
                      "ijklmnopjklmnopqklmnopqrlmnopqrsmnopqrstnopqrstu"),
            "cf5b16a778af8380036ce59e7b0492370b249b11e8f07a51afac45037afee9d1");
  EXPECT_EQ(Sha256Hex(std::string(1000000, 'a')),
            "cdc76e5c9914fb9281a1c7e284d73e67f1809a48a497200e046d39ccc7112cd0");
}

TEST(Sha256Test, FileMatchesBytesAcrossBlockBoundaries) {
  const fs::path d = TempDir("sha");
  // Lengths around the 64-byte block and 56-byte padding boundaries and the read buffer.
  for (size_t n : {size_t{55}, size_t{56}, size_t{63}, size_t{64}, size_t{65}, size_t{65536},
                   size_t{65537}, size_t{200000}}) {
    std::string s(n, '\0');
    for (size_t i = 0; i < n; ++i) s[i] = static_cast<char>((i * 131 + 7) & 0xff);
    WriteFileAtomic(d / "f.bin", s);
    EXPECT_EQ(Sha256File(d / "f.bin"), Sha256Hex(s)) << n;
  }
  EXPECT_THROW(Sha256File(d / "missing.bin"), Error);
  fs::remove_all(d);
}

TEST(FilesTest, AtomicWriteReplacesAndLeavesNoTemporaries) {
  const fs::path d = TempDir("atomic");
  WriteFileAtomic(d / "a.txt", "first");
  WriteFileAtomic(d / "a.txt", "second version");
  EXPECT_EQ(ReadFileToString(d / "a.txt"), "second version");
  int count = 0;
  for (const auto& e : fs::directory_iterator(d)) {
    (void)e;
    ++count;
  }
  EXPECT_EQ(count, 1);
  EXPECT_THROW(WriteFileAtomic(d / "no_such_dir" / "a.txt", "x"), Error);
  EXPECT_THROW(ReadFileToString(d / "missing.txt"), Error);
  // A folder where a file is expected: named, not std::ios_base::failure from its first read.
  fs::create_directories(d / "session.json");
  try {
    ReadFileToString(d / "session.json");
    ADD_FAILURE() << "a folder was read as a file";
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), (d / "session.json").string() + ": is a folder, not a file");
  }
  fs::remove(d / "session.json");
  // CommitFile moves a finished temporary into place.
  const fs::path tmp = TempPathFor(d / "b.txt");
  EXPECT_NE(tmp.string().find(".tmp-"), std::string::npos);
  { std::ofstream(tmp) << "committed"; }
  CommitFile(tmp, d / "b.txt");
  EXPECT_FALSE(fs::exists(tmp));
  EXPECT_EQ(ReadFileToString(d / "b.txt"), "committed");
  fs::remove_all(d);
}

TEST(FilesTest, ResolveInsideRefusesEscapes) {
  const fs::path d = TempDir("resolve");
  fs::create_directories(d / "frames");
  EXPECT_EQ(ResolveInside(d, "frames/000001.png"), d / "frames/000001.png");
  EXPECT_EQ(ResolveInside(d, "./frames/x.png"), d / "frames/x.png");
  EXPECT_THROW(ResolveInside(d, ""), Error);
  EXPECT_THROW(ResolveInside(d, "/etc/passwd"), Error);
  EXPECT_THROW(ResolveInside(d, "../x.png"), Error);
  EXPECT_THROW(ResolveInside(d, "frames/../../x.png"), Error);
  // A symlink inside the folder that points outside of it.
  fs::create_directory_symlink("/tmp", d / "escape");
  EXPECT_THROW(ResolveInside(d, "escape/x.png"), Error);
  // A symlink that stays inside is fine.
  fs::create_directory_symlink(d / "frames", d / "alias");
  EXPECT_NO_THROW(ResolveInside(d, "alias/x.png"));
  try {
    ResolveInside(d, "../x.png");
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("../x.png"), std::string::npos);
  }
  fs::remove_all(d);
}

TEST(FilesTest, AtomicWriteFailingAtAnyCallKeepsTheOldFileAndNoTemporary) {
  const fs::path d = TempDir("faulty");
  const std::string old_text = "old contents";
  const std::string new_text(100000, 'n');
  long calls = 0;
  {
    FaultyFileIo counter;
    ScopedFileIo use(counter);
    WriteFileAtomic(d / "a.txt", old_text);
    calls = counter.calls();
  }
  ASSERT_GE(calls, 4);  // open, write, fsync, rename, directory fsync
  for (int err : {ENOSPC, EROFS, EIO}) {
    for (long k = 0; k < calls; ++k) {
      SCOPED_TRACE("errno " + std::to_string(err) + " from call " + std::to_string(k));
      WriteFileAtomic(d / "a.txt", old_text);
      FaultyFileIo faulty(k, err);
      {
        ScopedFileIo use(faulty);
        try {
          WriteFileAtomic(d / "a.txt", new_text);
          ADD_FAILURE() << "the write succeeded";
        } catch (const Error& e) {
          const std::string m = e.what();
          EXPECT_NE(m.find((d / "a.txt").string()), std::string::npos) << m;
          if (err == ENOSPC) {
            EXPECT_NE(m.find("the disk is full"), std::string::npos) << m;
          } else if (err == EROFS) {
            EXPECT_NE(m.find("read-only"), std::string::npos) << m;
          }
        }
      }
      // Up to the rename the old file stands; a failing directory fsync after it leaves the
      // whole new file (and still reports the error).
      const std::string now = ReadFileToString(d / "a.txt");
      EXPECT_TRUE(now == old_text || (k == calls - 1 && now == new_text));
      for (const auto& e : fs::directory_iterator(d))
        EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
    }
  }
  fs::remove_all(d);
}

TEST(FilesTest, ImagesAreEncodedInMemoryAndWrittenThroughTheCheckedWriter) {
  const fs::path d = TempDir("image_io");
  Image im(5, 3, 3, PixelUnits::kDigital);
  for (size_t i = 0; i < im.data.size(); ++i) im.data[i] = static_cast<float>((i * 37) % 256);
  for (const char* name : {"f.png", "f.exr", "f.tif"}) {
    const fs::path p = d / name;
    const StoredType type = std::string(name) == "f.exr" ? StoredType::kHalf : StoredType::kUint8;
    const std::string bytes = EncodeImage(p.string(), im, type);
    FaultyFileIo counter;
    {
      ScopedFileIo use(counter);
      WriteImage(p.string(), im, type);
    }
    EXPECT_GE(counter.calls(), 4) << name;  // every byte went through the seam
    if (std::string(name) == "f.tif") {
      // OpenImageIO stamps a TIFF with the time (DateTime, fixed width): two encodings a
      // second apart differ there only.
      EXPECT_EQ(ReadFileToString(p).size(), bytes.size()) << name;
    } else {
      EXPECT_EQ(ReadFileToString(p), bytes) << name;
    }
    EXPECT_EQ(ReadImage(p.string()).data, im.data) << name;
    // A full disk leaves no file at all (the encoder never writes one itself).
    fs::remove(p);
    FaultyFileIo full(1, ENOSPC);
    ScopedFileIo use(full);
    EXPECT_THROW(WriteImage(p.string(), im, type), Error) << name;
    EXPECT_FALSE(fs::exists(p)) << name;
  }
  for (const auto& e : fs::directory_iterator(d))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
  fs::remove_all(d);
}

}  // namespace
TEST(FindOnPath, FindsProgramsAsTheShellDoes) {
  EXPECT_FALSE(FindOnPath("sh").empty());
  EXPECT_EQ(FindOnPath("/bin/sh"), "/bin/sh");
  EXPECT_TRUE(FindOnPath("rouen-no-such-program").empty());
  EXPECT_TRUE(FindOnPath("").empty());
}

}  // namespace rouen
