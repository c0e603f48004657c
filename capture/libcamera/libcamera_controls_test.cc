#include "capture/libcamera/libcamera_controls.h"

#include <gtest/gtest.h>
#include <libcamera/control_ids.h>

#include <array>
#include <cmath>
#include <limits>

namespace rouen::libcamera_internal {
namespace {

namespace lc = libcamera;

// Controls newer libcamera has and 0.0.3 lacks, made up here with ids 0.0.3 does not use.
const lc::Control<int32_t> kFakeExposureTimeMode(0x7f01, "ExposureTimeMode");
const lc::Control<int32_t> kFakeAnalogueGainMode(0x7f02, "AnalogueGainMode");

// A camera's ControlInfoMap from a list of (control, info) pairs; the id map is kept alive
// alongside since ControlInfoMap refers to it.
struct FakeCamera {
  lc::ControlIdMap idmap;
  lc::ControlInfoMap info;
  FakeCamera(std::initializer_list<std::pair<const lc::ControlId*, lc::ControlInfo>> entries) {
    lc::ControlInfoMap::Map map;
    for (const auto& [id, ci] : entries) {
      idmap[id->id()] = id;
      map.emplace(id, ci);
    }
    info = lc::ControlInfoMap(std::move(map), idmap);
  }
};

FakeCamera Libcamera003Camera() {
  return FakeCamera{
      {&lc::controls::AeEnable, lc::ControlInfo(false, true)},
      {&lc::controls::ExposureTime, lc::ControlInfo(int32_t{14}, int32_t{2000000})},
      {&lc::controls::AnalogueGain, lc::ControlInfo(1.0f, 16.0f)},
      {&lc::controls::FrameDurationLimits, lc::ControlInfo(int64_t{33333}, int64_t{2100000})},
  };
}

TEST(ExposureApi, DescribesALibcamera003Camera) {
  const FakeCamera cam = Libcamera003Camera();
  const ExposureApi api = DescribeExposureApi(cam.info);
  EXPECT_EQ(api.manual_switch, ExposureApi::ManualSwitch::kAeEnable);
  ASSERT_TRUE(api.ae_enable_id);
  EXPECT_EQ(*api.ae_enable_id, lc::controls::AeEnable.id());
  ASSERT_TRUE(api.exposure_min_s && api.exposure_max_s);
  EXPECT_DOUBLE_EQ(*api.exposure_min_s, 14e-6);
  EXPECT_DOUBLE_EQ(*api.exposure_max_s, 2.0);
  ASSERT_TRUE(api.gain_min && api.gain_max);
  EXPECT_DOUBLE_EQ(*api.gain_min, 1.0);
  EXPECT_DOUBLE_EQ(*api.gain_max, 16.0);
  EXPECT_EQ(api.frame_duration_min_us.value_or(-1), 33333);
  EXPECT_EQ(api.frame_duration_max_us.value_or(-1), 2100000);
  EXPECT_TRUE(api.Notes().empty());
  EXPECT_EQ(api.Summary(), "manual via AeEnable; exposure 14 us..2 s; gain 1..16");
}

TEST(ExposureApi, WritesAeEnableExposureGainAndFrameDurations) {
  const FakeCamera cam = Libcamera003Camera();
  const ExposureApi api = DescribeExposureApi(cam.info);
  lc::ControlList list(cam.info);
  SetManualExposure(api, {0.0123456, 2.5}, &list);
  EXPECT_EQ(list.get(lc::controls::AeEnable).value_or(true), false);
  EXPECT_EQ(list.get(lc::controls::ExposureTime).value_or(0), 12346);  // rounded µs
  EXPECT_FLOAT_EQ(list.get(lc::controls::AnalogueGain).value_or(0.f), 2.5f);
  const auto limits = list.get(lc::controls::FrameDurationLimits);
  ASSERT_TRUE(limits);
  EXPECT_EQ((*limits)[0], 33333);
  EXPECT_EQ((*limits)[1], 2100000);
  EXPECT_FALSE(list.contains(kFakeExposureTimeMode.id()));
}

TEST(ExposureApi, PrefersModeControlsOfNewerLibcamera) {
  const FakeCamera cam{
      {&kFakeExposureTimeMode, lc::ControlInfo(int32_t{0}, int32_t{1})},
      {&kFakeAnalogueGainMode, lc::ControlInfo(int32_t{0}, int32_t{1})},
      {&lc::controls::ExposureTime, lc::ControlInfo(int32_t{1}, int32_t{66666})},
      {&lc::controls::AnalogueGain, lc::ControlInfo(1.0f, 8.0f)},
  };
  const ExposureApi api = DescribeExposureApi(cam.info);
  EXPECT_EQ(api.manual_switch, ExposureApi::ManualSwitch::kModeControls);
  EXPECT_EQ(api.Summary(), "manual via ExposureTimeMode; exposure 1 us..0.066666 s; gain 1..8");
  lc::ControlList list(cam.info);
  SetManualExposure(api, {0.01, 4.0}, &list);
  ASSERT_TRUE(list.contains(kFakeExposureTimeMode.id()));
  ASSERT_TRUE(list.contains(kFakeAnalogueGainMode.id()));
  EXPECT_EQ(list.get(kFakeExposureTimeMode.id()).get<int32_t>(), 1);  // Manual
  EXPECT_EQ(list.get(kFakeAnalogueGainMode.id()).get<int32_t>(), 1);
  EXPECT_FALSE(list.contains(lc::controls::AeEnable.id()));
  EXPECT_EQ(list.get(lc::controls::ExposureTime).value_or(0), 10000);
  EXPECT_FALSE(list.contains(lc::controls::FrameDurationLimits.id()));  // camera has none
}

TEST(ExposureApi, CameraWithoutSwitchOrGainIsReportedAndNothingBogusIsWritten) {
  const FakeCamera cam{
      {&lc::controls::ExposureTime, lc::ControlInfo(int32_t{100}, int32_t{50000})},
  };
  const ExposureApi api = DescribeExposureApi(cam.info);
  EXPECT_EQ(api.manual_switch, ExposureApi::ManualSwitch::kNone);
  EXPECT_FALSE(api.gain_min);
  const auto notes = api.Notes();
  ASSERT_EQ(notes.size(), 2u);
  EXPECT_NE(notes[0].find("AeEnable"), std::string::npos);
  EXPECT_NE(notes[1].find("AnalogueGain"), std::string::npos);
  lc::ControlList list(cam.info);
  SetManualExposure(api, {0.02, 3.0}, &list);
  EXPECT_EQ(list.size(), 1u);
  EXPECT_EQ(list.get(lc::controls::ExposureTime).value_or(0), 20000);
}

TEST(ExposureApi, EmptyCameraHasNoControls) {
  const ExposureApi api = DescribeExposureApi(lc::ControlInfoMap());
  EXPECT_EQ(api.manual_switch, ExposureApi::ManualSwitch::kNone);
  EXPECT_EQ(api.Notes().size(), 3u);
  EXPECT_EQ(api.Summary(), "no manual exposure switch; no exposure control; no gain control");
  // Unconstrained: only µs quantisation and float gain.
  const ExposureSetting s = ClampToApi(api, {0.5, 0.25});
  EXPECT_DOUBLE_EQ(s.exposure_s, 0.5);
  EXPECT_DOUBLE_EQ(s.gain, 0.25);
}

TEST(ExposureApi, MicrosecondConversion) {
  EXPECT_EQ(ExposureSecondsToMicroseconds(1.0 / 250), 4000);
  EXPECT_EQ(ExposureSecondsToMicroseconds(1.4e-6), 1);
  EXPECT_EQ(ExposureSecondsToMicroseconds(1.6e-6), 2);
  EXPECT_EQ(ExposureSecondsToMicroseconds(0.0), 1);
  EXPECT_EQ(ExposureSecondsToMicroseconds(-3.0), 1);
  EXPECT_EQ(ExposureSecondsToMicroseconds(std::nan("")), 1);
  EXPECT_EQ(ExposureSecondsToMicroseconds(1e9), std::numeric_limits<int32_t>::max());
  EXPECT_DOUBLE_EQ(MicrosecondsToSeconds(250000), 0.25);
}

TEST(ExposureApi, ClampsToTheCameraRangeAndQuantises) {
  const FakeCamera cam = Libcamera003Camera();
  const ExposureApi api = DescribeExposureApi(cam.info);
  EXPECT_DOUBLE_EQ(ClampToApi(api, {30.0, 1.0}).exposure_s, 2.0);
  EXPECT_DOUBLE_EQ(ClampToApi(api, {1e-7, 1.0}).exposure_s, 14e-6);
  EXPECT_DOUBLE_EQ(ClampToApi(api, {0.0100004, 1.0}).exposure_s, 0.01);
  EXPECT_DOUBLE_EQ(ClampToApi(api, {0.01, 0.5}).gain, 1.0);
  EXPECT_DOUBLE_EQ(ClampToApi(api, {0.01, 100.0}).gain, 16.0);
  // The gain given back is exactly what a float control carries.
  EXPECT_EQ(ClampToApi(api, {0.01, 1.1}).gain, static_cast<double>(1.1f));
}

TEST(AppliedMetadata, ReadsExposureGainAndTimestamp) {
  lc::ControlList meta(lc::controls::controls);
  meta.set(lc::controls::ExposureTime, int32_t{12345});
  meta.set(lc::controls::AnalogueGain, 2.5f);
  meta.set(lc::controls::SensorTimestamp, int64_t{987654321012});
  const AppliedMetadata a = ReadAppliedMetadata(meta);
  ASSERT_TRUE(a.exposure_s && a.gain && a.sensor_timestamp_ns);
  EXPECT_DOUBLE_EQ(*a.exposure_s, 0.012345);
  EXPECT_DOUBLE_EQ(*a.gain, 2.5);
  EXPECT_EQ(*a.sensor_timestamp_ns, 987654321012);
}

TEST(AppliedMetadata, MissingOrNonsenseValuesAreAbsent) {
  lc::ControlList empty(lc::controls::controls);
  const AppliedMetadata none = ReadAppliedMetadata(empty);
  EXPECT_FALSE(none.exposure_s);
  EXPECT_FALSE(none.gain);
  EXPECT_FALSE(none.sensor_timestamp_ns);
  lc::ControlList zero(lc::controls::controls);
  zero.set(lc::controls::ExposureTime, int32_t{0});
  zero.set(lc::controls::AnalogueGain, -1.0f);
  const AppliedMetadata z = ReadAppliedMetadata(zero);
  EXPECT_FALSE(z.exposure_s);
  EXPECT_FALSE(z.gain);
}

TEST(StreamAdjustments, ReportsOnlyWhatWasAskedAndChanged) {
  StreamSetting asked{"YUYV", 1920, 1080, 4};
  StreamSetting got{"NV12", 1920, 1088, 6};
  const auto adj = DescribeStreamAdjustments(asked, got);
  ASSERT_EQ(adj.size(), 3u);
  EXPECT_EQ(adj[0], "pixel format YUYV -> NV12");
  EXPECT_EQ(adj[1], "size 1920x1080 -> 1920x1088");
  EXPECT_EQ(adj[2], "buffer count 4 -> 6");
  EXPECT_TRUE(DescribeStreamAdjustments(asked, asked).empty());
  // Defaults left to the camera are not adjustments.
  EXPECT_TRUE(DescribeStreamAdjustments(StreamSetting{}, got).empty());
}

TEST(SensorTimestamp, ShiftsByTheClockOffset) {
  // Clock read 2.5 ms after the frame's timestamp: the frame was 2.5 ms before now.
  const int64_t utc_now = 1'787'000'000'000'000'000;
  EXPECT_EQ(SensorTimestampToUtcNs(1'000'000'000, 1'002'500'000, utc_now), utc_now - 2'500'000);
}

}  // namespace
}  // namespace rouen::libcamera_internal
