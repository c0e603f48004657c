// Internal to rouen_libcamera: the one place where rouen's exposure settings (seconds, linear
// analogue gain) meet libcamera's controls. libcamera 0.0.3 switches manual exposure with
// AeEnable=false; newer libcamera (0.5+) replaces AeEnable with ExposureTimeMode and
// AnalogueGainMode (Manual = 1). The switch is found by control *name* in the camera's
// ControlInfoMap, so both generations are handled here without version #ifs.
#pragma once

#include <libcamera/controls.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace rouen::libcamera_internal {

// A rouen exposure setting: exposure time in seconds, linear analogue gain (1 = unity).
struct ExposureSetting {
  double exposure_s = 0;
  double gain = 1;
};

// How a camera turns automatic exposure off and what ranges it accepts (from
// Camera::controls()).
struct ExposureApi {
  enum class ManualSwitch {
    kAeEnable,      // libcamera <= 0.4: AeEnable = false
    kModeControls,  // libcamera >= 0.5: ExposureTimeMode = AnalogueGainMode = Manual (1)
    kNone,          // the camera offers no switch; ExposureTime may be ignored by its AE
  };
  ManualSwitch manual_switch = ManualSwitch::kNone;
  std::optional<unsigned> ae_enable_id, exposure_time_mode_id, analogue_gain_mode_id;
  std::optional<unsigned> exposure_time_id, analogue_gain_id, frame_duration_limits_id;
  // Ranges reported by the camera (seconds; linear gain). Absent when the camera gave none.
  std::optional<double> exposure_min_s, exposure_max_s;
  std::optional<double> gain_min, gain_max;
  // Frame duration limits (µs) the camera reports; we request the whole span so that long
  // exposures are not cut short by the frame rate.
  std::optional<int64_t> frame_duration_min_us, frame_duration_max_us;

  // Human-readable notes about what is missing ("no AnalogueGain control: gain stays at the
  // sensor's default"), for the configure report.
  std::vector<std::string> Notes() const;
  // One line for `rouen devices`: "manual via AeEnable; exposure 14 us..2 s; gain 1..16".
  std::string Summary() const;
};

// Reads the controls a camera offers. Pure: works on any ControlInfoMap, including synthetic
// ones built in tests.
ExposureApi DescribeExposureApi(const libcamera::ControlInfoMap& info);

// Seconds -> libcamera ExposureTime microseconds (rounded to the nearest µs, at least 1 µs,
// capped at INT32_MAX). Non-finite or non-positive input gives 1 µs.
int32_t ExposureSecondsToMicroseconds(double seconds);
double MicrosecondsToSeconds(int64_t microseconds);

// Clamps a setting to the camera's ranges and quantises the exposure to whole µs (what
// libcamera can carry). Gains below 1 are raised to the camera's minimum when known.
ExposureSetting ClampToApi(const ExposureApi& api, const ExposureSetting& wanted);

// Writes the manual-exposure controls for `setting` into `controls` (a request's control
// list): the manual switch, ExposureTime (µs), AnalogueGain, and FrameDurationLimits spanning
// the camera's whole range when it has one. Controls the camera lacks are left out.
void SetManualExposure(const ExposureApi& api, const ExposureSetting& setting,
                       libcamera::ControlList* controls);

// What a completed request's metadata says was applied.
struct AppliedMetadata {
  std::optional<double> exposure_s;            // from ExposureTime (µs)
  std::optional<double> gain;                  // from AnalogueGain
  std::optional<int64_t> sensor_timestamp_ns;  // SensorTimestamp
};
AppliedMetadata ReadAppliedMetadata(const libcamera::ControlList& metadata);

// A stream configuration as asked and as validated, for the configure report.
struct StreamSetting {
  std::string pixel_format;   // libcamera name ("NV12", "SRGGB10_CSI2P"); empty = default
  int width = 0, height = 0;  // 0 = default
  unsigned buffer_count = 0;  // 0 = default
};
// Human-readable adjustments validate() made ("pixel format YUYV -> NV12"); a field that was
// left to the default is not reported.
std::vector<std::string> DescribeStreamAdjustments(const StreamSetting& asked,
                                                   const StreamSetting& got);

// Converts a sensor timestamp (ns on the sensor's clock, CLOCK_MONOTONIC or CLOCK_BOOTTIME)
// to UTC ns, from a simultaneous reading of that clock and of the UTC (realtime) clock.
int64_t SensorTimestampToUtcNs(int64_t sensor_ns, int64_t clock_now_ns, int64_t utc_now_ns);

}  // namespace rouen::libcamera_internal
