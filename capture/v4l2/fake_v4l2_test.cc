// The fake must be strict: the calls a buggy driver makes fail like the kernel's would.
#include "capture/v4l2/fake_v4l2.h"

#include <fcntl.h>
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/mman.h>

#include <cerrno>

namespace rouen {
namespace {

// Opens the fake and brings its queue to `buffers` mmapped buffers (not queued).
struct Session {
  explicit Session(FakeV4l2Options o = {}, int buffers = 3) : fake(std::move(o)) {
    fd = fake.Open("/dev/video0", O_RDWR | O_NONBLOCK);
    EXPECT_GE(fd, 0);
    v4l2_requestbuffers req{};
    req.count = static_cast<uint32_t>(buffers);
    req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    req.memory = V4L2_MEMORY_MMAP;
    EXPECT_EQ(fake.Ioctl(fd, VIDIOC_REQBUFS, &req), 0);
    count = static_cast<int>(req.count);
    for (int i = 0; i < count; ++i) {
      v4l2_buffer b = Buf(i);
      EXPECT_EQ(fake.Ioctl(fd, VIDIOC_QUERYBUF, &b), 0);
      lengths.push_back(b.length);
      maps.push_back(fake.Mmap(b.length, PROT_READ, MAP_SHARED, fd, b.m.offset));
      EXPECT_NE(maps.back(), MAP_FAILED);
    }
  }
  static v4l2_buffer Buf(int index) {
    v4l2_buffer b{};
    b.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    b.memory = V4L2_MEMORY_MMAP;
    b.index = static_cast<uint32_t>(index);
    return b;
  }
  int Q(int index) {
    v4l2_buffer b = Buf(index);
    return fake.Ioctl(fd, VIDIOC_QBUF, &b);
  }
  int Dq(v4l2_buffer* out) {
    *out = Buf(0);
    return fake.Ioctl(fd, VIDIOC_DQBUF, out);
  }
  int StreamOn() {
    int type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
    return fake.Ioctl(fd, VIDIOC_STREAMON, &type);
  }
  int SetCtrl(uint32_t id, int value) {
    v4l2_control c{id, value};
    return fake.Ioctl(fd, VIDIOC_S_CTRL, &c);
  }
  FakeV4l2Device fake;
  int fd = -1, count = 0;
  std::vector<uint32_t> lengths;
  std::vector<void*> maps;
};

TEST(FakeV4l2, DqbufBeforeStreamonFails) {
  Session s;
  ASSERT_EQ(s.Q(0), 0);
  v4l2_buffer b;
  errno = 0;
  EXPECT_EQ(s.Dq(&b), -1);
  EXPECT_EQ(errno, EINVAL);
  ASSERT_FALSE(s.fake.Misuse().empty());
  EXPECT_NE(s.fake.Misuse().back().find("not streaming"), std::string::npos);
}

TEST(FakeV4l2, QbufOutOfRangeOrTwiceFails) {
  Session s;
  EXPECT_EQ(s.Q(s.count), -1);
  EXPECT_EQ(errno, EINVAL);
  EXPECT_EQ(s.Q(-1), -1);
  EXPECT_EQ(errno, EINVAL);
  EXPECT_EQ(s.Q(0), 0);
  EXPECT_EQ(s.Q(0), -1);
  EXPECT_EQ(errno, EINVAL);
  EXPECT_EQ(s.fake.Misuse().size(), 3u);
}

TEST(FakeV4l2, MmapAndMunmapAreChecked) {
  Session s;
  EXPECT_EQ(s.fake.Mmap(s.lengths[0], PROT_READ, MAP_SHARED, s.fd, 12345), MAP_FAILED);
  EXPECT_EQ(s.fake.Mmap(s.lengths[0], PROT_READ, MAP_PRIVATE, s.fd, 0), MAP_FAILED);
  EXPECT_EQ(s.fake.Mmap(s.lengths[0] + 1, PROT_READ, MAP_SHARED, s.fd, 0), MAP_FAILED);
  int dummy;
  EXPECT_EQ(s.fake.Munmap(&dummy, 4), -1);
  EXPECT_EQ(s.fake.Misuse().size(), 4u);
  EXPECT_EQ(s.fake.Mappings(), s.count);
  for (int i = 0; i < s.count; ++i) EXPECT_EQ(s.fake.Munmap(s.maps[i], s.lengths[i]), 0);
  EXPECT_EQ(s.fake.Mappings(), 0);
}

TEST(FakeV4l2, UnknownIoctlsAndControls) {
  Session s;
  int dummy = 0;
  EXPECT_EQ(s.fake.Ioctl(s.fd, VIDIOC_G_PARM, &dummy), -1);
  EXPECT_EQ(errno, ENOTTY);  // the kernel's answer to an ioctl a driver lacks
  EXPECT_EQ(s.SetCtrl(V4L2_CID_HUE, 3), -1);
  EXPECT_EQ(errno, EINVAL);
  v4l2_queryctrl q{};
  q.id = V4L2_CID_ZOOM_ABSOLUTE;
  EXPECT_EQ(s.fake.Ioctl(s.fd, VIDIOC_QUERYCTRL, &q), -1);
  EXPECT_EQ(errno, EINVAL);
  EXPECT_EQ(s.fake.Ioctl(12345, VIDIOC_QUERYCAP, &q), -1);
  EXPECT_EQ(errno, EBADF);
}

TEST(FakeV4l2, ControlsEnumerateClampAndRespectAutoMode) {
  Session s;
  // Enumeration with NEXT_CTRL visits every control once, in id order.
  std::vector<uint32_t> ids;
  v4l2_queryctrl q{};
  q.id = V4L2_CTRL_FLAG_NEXT_CTRL;
  while (s.fake.Ioctl(s.fd, VIDIOC_QUERYCTRL, &q) == 0) {
    ids.push_back(q.id);
    q.id |= V4L2_CTRL_FLAG_NEXT_CTRL;
  }
  EXPECT_EQ(ids.size(), 5u);
  // Exposure time is inactive while auto exposure is on.
  EXPECT_EQ(s.SetCtrl(V4L2_CID_EXPOSURE_ABSOLUTE, 100), -1);
  EXPECT_EQ(errno, EACCES);
  EXPECT_EQ(s.SetCtrl(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_AUTO), -1);  // not in the menu
  EXPECT_EQ(errno, EINVAL);
  ASSERT_EQ(s.SetCtrl(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL), 0);
  v4l2_control c{V4L2_CID_EXPOSURE_ABSOLUTE, 999999};
  ASSERT_EQ(s.fake.Ioctl(s.fd, VIDIOC_S_CTRL, &c), 0);
  EXPECT_EQ(c.value, 2047);  // clamped like uvcvideo
  EXPECT_EQ(*s.fake.Control(V4L2_CID_EXPOSURE_ABSOLUTE), 2047);
}

TEST(FakeV4l2, FormatChangesAreRefusedWhileBuffersExist) {
  Session s;
  v4l2_format f{};
  f.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  f.fmt.pix.pixelformat = V4L2_PIX_FMT_YUYV;
  f.fmt.pix.width = 64;
  f.fmt.pix.height = 48;
  EXPECT_EQ(s.fake.Ioctl(s.fd, VIDIOC_S_FMT, &f), -1);
  EXPECT_EQ(errno, EBUSY);
  // TRY_FMT is always allowed and substitutes what it cannot do.
  f.fmt.pix.pixelformat = V4L2_PIX_FMT_RGB24;
  f.fmt.pix.width = 1000;
  ASSERT_EQ(s.fake.Ioctl(s.fd, VIDIOC_TRY_FMT, &f), 0);
  EXPECT_NE(f.fmt.pix.pixelformat, static_cast<uint32_t>(V4L2_PIX_FMT_RGB24));
  // A second opener cannot take the queue.
  const int fd2 = s.fake.Open("/dev/video0", O_RDWR);
  v4l2_requestbuffers req{};
  req.count = 2;
  req.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  req.memory = V4L2_MEMORY_MMAP;
  EXPECT_EQ(s.fake.Ioctl(fd2, VIDIOC_REQBUFS, &req), -1);
  EXPECT_EQ(errno, EBUSY);
  EXPECT_EQ(s.fake.Close(fd2), 0);
}

TEST(FakeV4l2, PollAndDqbufFollowTheQueue) {
  Session s;
  short rev = 0;
  EXPECT_EQ(s.fake.Poll(s.fd, POLLIN, &rev, 100), 1);
  EXPECT_TRUE(rev & POLLERR);  // not streaming
  ASSERT_EQ(s.StreamOn(), 0);
  EXPECT_EQ(s.fake.Poll(s.fd, POLLIN, &rev, 100), 0);  // nothing queued: times out
  v4l2_buffer b;
  EXPECT_EQ(s.Dq(&b), -1);
  EXPECT_EQ(errno, EAGAIN);
  for (int i = 0; i < s.count; ++i) ASSERT_EQ(s.Q(i), 0);
  EXPECT_EQ(s.fake.Poll(s.fd, POLLIN, &rev, 100), 1);
  EXPECT_TRUE(rev & POLLIN);
  uint32_t last_seq = 0;
  for (int i = 0; i < s.count; ++i) {
    ASSERT_EQ(s.Dq(&b), 0);
    EXPECT_EQ(b.flags & V4L2_BUF_FLAG_TIMESTAMP_MASK, V4L2_BUF_FLAG_TIMESTAMP_MONOTONIC);
    EXPECT_GT(b.bytesused, 0u);
    if (i > 0) {
      EXPECT_EQ(b.sequence, last_seq + 1);
    }
    last_seq = b.sequence;
  }
  EXPECT_TRUE(s.fake.Misuse().empty());
}

TEST(FakeV4l2, ControlLatencyInFrames) {
  FakeV4l2Options o;
  o.control_latency_frames = 2;
  o.fill = FakeV4l2Options::Fill::kOnPoll;
  Session s(o, 2);
  ASSERT_EQ(s.SetCtrl(V4L2_CID_EXPOSURE_AUTO, V4L2_EXPOSURE_MANUAL), 0);
  ASSERT_EQ(s.SetCtrl(V4L2_CID_EXPOSURE_ABSOLUTE, 25), 0);
  ASSERT_EQ(s.StreamOn(), 0);
  std::vector<int> exposures;
  v4l2_buffer b;
  for (int k = 0; k < 6; ++k) {
    if (k == 3) {
      ASSERT_EQ(s.SetCtrl(V4L2_CID_EXPOSURE_ABSOLUTE, 100), 0);
    }
    ASSERT_EQ(s.Q(0), 0);
    ASSERT_EQ(s.Dq(&b), 0);
    exposures.push_back(s.fake.Frame(b.sequence)->exposure_raw);
  }
  // Manual mode and 25 set before frame 0 -> show from frame 2 (frames 0, 1 are still
  // auto-exposed); 100 set before frame 3 -> shows from frame 5.
  EXPECT_NE(exposures[0], 25);
  EXPECT_NE(exposures[1], 25);
  EXPECT_EQ(std::vector<int>(exposures.begin() + 2, exposures.end()),
            (std::vector<int>{25, 25, 25, 100}));
  EXPECT_TRUE(s.fake.Frame(b.sequence - 5)->auto_exposure);
  EXPECT_FALSE(s.fake.Frame(b.sequence)->auto_exposure);
  // Brightness follows exposure (reflectance x 20000 DN/s x t): 4x the exposure, ~4x the
  // mean while nothing saturates.
  const double m25 = s.fake.Frame(b.sequence - 1)->MeanRgb();
  const double m100 = s.fake.Frame(b.sequence)->MeanRgb();
  EXPECT_NEAR(m100 / m25, 4.0, 0.1);
}

TEST(FakeV4l2, VanishesWithEnodevAndPollerr) {
  FakeV4l2Options o;
  o.vanish_after_frames = 2;
  o.fill = FakeV4l2Options::Fill::kOnPoll;
  Session s(o, 3);
  ASSERT_EQ(s.StreamOn(), 0);
  for (int i = 0; i < s.count; ++i) ASSERT_EQ(s.Q(i), 0);
  v4l2_buffer b;
  ASSERT_EQ(s.Dq(&b), 0);
  ASSERT_EQ(s.Dq(&b), 0);
  EXPECT_EQ(s.Dq(&b), -1);
  EXPECT_EQ(errno, ENODEV);
  short rev = 0;
  EXPECT_EQ(s.fake.Poll(s.fd, POLLIN, &rev, 100), 1);
  EXPECT_TRUE(rev & POLLERR);
  EXPECT_EQ(s.Q(0), -1);
  EXPECT_EQ(errno, ENODEV);
  EXPECT_EQ(s.fake.Open("/dev/video0", O_RDWR), -1);
  EXPECT_EQ(errno, ENOENT);
  // Memory and descriptors can still be released.
  for (int i = 0; i < s.count; ++i) EXPECT_EQ(s.fake.Munmap(s.maps[i], s.lengths[i]), 0);
  EXPECT_EQ(s.fake.Close(s.fd), 0);
  EXPECT_EQ(s.fake.OpenFds(), 0);
  EXPECT_EQ(s.fake.Mappings(), 0);
}

TEST(FakeV4l2, MetadataNodeIsNotACaptureDevice) {
  FakeV4l2Options meta;
  meta.path = "/dev/video1";
  meta.video_capture = false;
  FakeV4l2Device fake(std::vector<FakeV4l2Options>{FakeV4l2Options{}, meta});
  EXPECT_EQ(fake.ListDevices(), (std::vector<std::string>{"/dev/video0", "/dev/video1"}));
  const int fd = fake.Open("/dev/video1", O_RDWR);
  v4l2_capability cap{};
  ASSERT_EQ(fake.Ioctl(fd, VIDIOC_QUERYCAP, &cap), 0);
  EXPECT_FALSE(cap.device_caps & V4L2_CAP_VIDEO_CAPTURE);
  EXPECT_TRUE(cap.device_caps & V4L2_CAP_META_CAPTURE);
  v4l2_fmtdesc d{};
  d.type = V4L2_BUF_TYPE_VIDEO_CAPTURE;
  EXPECT_EQ(fake.Ioctl(fd, VIDIOC_ENUM_FMT, &d), -1);
  EXPECT_EQ(errno, EINVAL);
  fake.Close(fd);
}

}  // namespace
}  // namespace rouen
