#include "capture/libcamera/libcamera_controls.h"

#include <libcamera/control_ids.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <limits>

namespace rouen::libcamera_internal {
namespace {

// ControlValue::get<T>() must only be called for the matching type; these read a number of
// any numeric type, or nothing.
std::optional<double> NumberOf(const libcamera::ControlValue& v) {
  if (v.isArray()) return std::nullopt;
  switch (v.type()) {
    case libcamera::ControlTypeByte:
      return static_cast<double>(v.get<uint8_t>());
    case libcamera::ControlTypeInteger32:
      return static_cast<double>(v.get<int32_t>());
    case libcamera::ControlTypeInteger64:
      return static_cast<double>(v.get<int64_t>());
    case libcamera::ControlTypeFloat:
      return static_cast<double>(v.get<float>());
    default:
      return std::nullopt;
  }
}

}  // namespace

std::vector<std::string> ExposureApi::Notes() const {
  std::vector<std::string> notes;
  if (manual_switch == ManualSwitch::kNone) {
    notes.emplace_back(
        "camera offers neither AeEnable nor ExposureTimeMode: automatic exposure cannot be "
        "switched off, applied exposure is read back from each frame's metadata");
  }
  if (!exposure_time_id) {
    notes.emplace_back("no ExposureTime control: exposure cannot be set");
  }
  if (!analogue_gain_id) {
    notes.emplace_back("no AnalogueGain control: gain stays at the sensor's default");
  }
  return notes;
}

std::string ExposureApi::Summary() const {
  auto num = [](double v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", v);
    return std::string(buf);
  };
  auto exposure = [&](double s) { return s < 1e-3 ? num(s * 1e6) + " us" : num(s) + " s"; };
  std::string out;
  switch (manual_switch) {
    case ManualSwitch::kAeEnable:
      out = "manual via AeEnable";
      break;
    case ManualSwitch::kModeControls:
      out = "manual via ExposureTimeMode";
      break;
    case ManualSwitch::kNone:
      out = "no manual exposure switch";
      break;
  }
  if (!exposure_time_id) {
    out += "; no exposure control";
  } else if (exposure_min_s && exposure_max_s) {
    out += "; exposure " + exposure(*exposure_min_s) + ".." + exposure(*exposure_max_s);
  } else {
    out += "; exposure (range not reported)";
  }
  if (!analogue_gain_id) {
    out += "; no gain control";
  } else if (gain_min && gain_max) {
    out += "; gain " + num(*gain_min) + ".." + num(*gain_max);
  } else {
    out += "; gain (range not reported)";
  }
  return out;
}

ExposureApi DescribeExposureApi(const libcamera::ControlInfoMap& info) {
  ExposureApi api;
  for (const auto& [id, range] : info) {
    const std::string& name = id->name();
    if (name == "AeEnable") {
      api.ae_enable_id = id->id();
    } else if (name == "ExposureTimeMode") {
      api.exposure_time_mode_id = id->id();
    } else if (name == "AnalogueGainMode") {
      api.analogue_gain_mode_id = id->id();
    } else if (name == "ExposureTime") {
      api.exposure_time_id = id->id();
      const auto lo = NumberOf(range.min()), hi = NumberOf(range.max());
      if (lo && *lo > 0) api.exposure_min_s = MicrosecondsToSeconds(std::llround(*lo));
      if (hi && *hi > 0 && (!lo || *hi >= *lo)) {
        api.exposure_max_s = MicrosecondsToSeconds(std::llround(*hi));
      }
    } else if (name == "AnalogueGain") {
      api.analogue_gain_id = id->id();
      const auto lo = NumberOf(range.min()), hi = NumberOf(range.max());
      if (lo && *lo > 0) api.gain_min = *lo;
      if (hi && *hi > 0 && (!lo || *hi >= *lo)) api.gain_max = *hi;
    } else if (name == "FrameDurationLimits") {
      api.frame_duration_limits_id = id->id();
      const auto lo = NumberOf(range.min()), hi = NumberOf(range.max());
      if (lo && hi && *lo > 0 && *hi >= *lo) {
        api.frame_duration_min_us = std::llround(*lo);
        api.frame_duration_max_us = std::llround(*hi);
      }
    }
  }
  // Newer libcamera has both mode controls; prefer them when present, since AeEnable is gone
  // there. Exposure mode alone is enough to stop AE changing the exposure time.
  if (api.exposure_time_mode_id) {
    api.manual_switch = ExposureApi::ManualSwitch::kModeControls;
  } else if (api.ae_enable_id) {
    api.manual_switch = ExposureApi::ManualSwitch::kAeEnable;
  }
  return api;
}

int32_t ExposureSecondsToMicroseconds(double seconds) {
  if (!std::isfinite(seconds) || seconds <= 0) return 1;
  const double us = std::round(seconds * 1e6);
  if (us >= static_cast<double>(std::numeric_limits<int32_t>::max())) {
    return std::numeric_limits<int32_t>::max();
  }
  return std::max<int32_t>(1, static_cast<int32_t>(us));
}

double MicrosecondsToSeconds(int64_t microseconds) {
  return static_cast<double>(microseconds) * 1e-6;
}

ExposureSetting ClampToApi(const ExposureApi& api, const ExposureSetting& wanted) {
  ExposureSetting s = wanted;
  if (api.exposure_min_s) s.exposure_s = std::max(s.exposure_s, *api.exposure_min_s);
  if (api.exposure_max_s) s.exposure_s = std::min(s.exposure_s, *api.exposure_max_s);
  s.exposure_s = MicrosecondsToSeconds(ExposureSecondsToMicroseconds(s.exposure_s));
  if (api.gain_min) s.gain = std::max(s.gain, *api.gain_min);
  if (api.gain_max) s.gain = std::min(s.gain, *api.gain_max);
  // libcamera carries the gain as a float: give back exactly what will be sent.
  s.gain = static_cast<double>(static_cast<float>(s.gain));
  return s;
}

void SetManualExposure(const ExposureApi& api, const ExposureSetting& setting,
                       libcamera::ControlList* controls) {
  switch (api.manual_switch) {
    case ExposureApi::ManualSwitch::kAeEnable:
      controls->set(*api.ae_enable_id, libcamera::ControlValue(false));
      break;
    case ExposureApi::ManualSwitch::kModeControls:
      // ExposureTimeModeManual = AnalogueGainModeManual = 1 in libcamera >= 0.5.
      controls->set(*api.exposure_time_mode_id, libcamera::ControlValue(int32_t{1}));
      if (api.analogue_gain_mode_id) {
        controls->set(*api.analogue_gain_mode_id, libcamera::ControlValue(int32_t{1}));
      }
      break;
    case ExposureApi::ManualSwitch::kNone:
      break;
  }
  if (api.exposure_time_id) {
    controls->set(*api.exposure_time_id,
                  libcamera::ControlValue(ExposureSecondsToMicroseconds(setting.exposure_s)));
  }
  if (api.analogue_gain_id && std::isfinite(setting.gain) && setting.gain > 0) {
    controls->set(*api.analogue_gain_id, libcamera::ControlValue(static_cast<float>(setting.gain)));
  }
  if (api.frame_duration_limits_id && api.frame_duration_min_us && api.frame_duration_max_us) {
    const std::array<int64_t, 2> limits{*api.frame_duration_min_us, *api.frame_duration_max_us};
    controls->set(*api.frame_duration_limits_id,
                  libcamera::ControlValue(libcamera::Span<const int64_t, 2>(limits)));
  }
}

AppliedMetadata ReadAppliedMetadata(const libcamera::ControlList& metadata) {
  AppliedMetadata out;
  auto read = [&](unsigned id) -> std::optional<double> {
    if (!metadata.contains(id)) return std::nullopt;
    return NumberOf(metadata.get(id));
  };
  if (const auto us = read(libcamera::controls::ExposureTime.id()); us && *us > 0) {
    out.exposure_s = *us * 1e-6;
  }
  if (const auto g = read(libcamera::controls::AnalogueGain.id()); g && *g > 0) {
    out.gain = *g;
  }
  if (metadata.contains(libcamera::controls::SensorTimestamp.id())) {
    const libcamera::ControlValue& v = metadata.get(libcamera::controls::SensorTimestamp.id());
    if (!v.isArray() && v.type() == libcamera::ControlTypeInteger64) {
      out.sensor_timestamp_ns = v.get<int64_t>();
    }
  }
  return out;
}

std::vector<std::string> DescribeStreamAdjustments(const StreamSetting& asked,
                                                   const StreamSetting& got) {
  std::vector<std::string> out;
  if (!asked.pixel_format.empty() && asked.pixel_format != got.pixel_format) {
    out.push_back("pixel format " + asked.pixel_format + " -> " + got.pixel_format);
  }
  const bool size_asked = asked.width > 0 || asked.height > 0;
  if (size_asked && (asked.width != got.width || asked.height != got.height)) {
    auto wh = [](int w, int h) {
      return (w > 0 ? std::to_string(w) : std::string("?")) + "x" +
             (h > 0 ? std::to_string(h) : std::string("?"));
    };
    out.push_back("size " + wh(asked.width, asked.height) + " -> " + wh(got.width, got.height));
  }
  if (asked.buffer_count > 0 && asked.buffer_count != got.buffer_count) {
    out.push_back("buffer count " + std::to_string(asked.buffer_count) + " -> " +
                  std::to_string(got.buffer_count));
  }
  return out;
}

int64_t SensorTimestampToUtcNs(int64_t sensor_ns, int64_t clock_now_ns, int64_t utc_now_ns) {
  return utc_now_ns - (clock_now_ns - sensor_ns);
}

}  // namespace rouen::libcamera_internal
