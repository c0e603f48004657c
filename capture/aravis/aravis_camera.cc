#include "capture/aravis/aravis_camera.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <thread>

#include "capture/aravis/aravis_internal.h"
#include "core/error.h"

namespace rouen {
namespace {

// Takes the message out of a GError (and frees it); empty when there was no error.
std::string TakeError(GError*& error) {
  if (error == nullptr) return "";
  std::string msg = error->message ? error->message : "unknown Aravis error";
  g_clear_error(&error);
  return msg;
}

std::string Str(const char* s) { return s ? s : ""; }

const char* StatusName(ArvBufferStatus s) {
  switch (s) {
    case ARV_BUFFER_STATUS_SUCCESS:
      return "success";
    case ARV_BUFFER_STATUS_CLEARED:
      return "cleared";
    case ARV_BUFFER_STATUS_TIMEOUT:
      return "timeout before all packets arrived";
    case ARV_BUFFER_STATUS_MISSING_PACKETS:
      return "missing packets";
    case ARV_BUFFER_STATUS_WRONG_PACKET_ID:
      return "wrong packet id";
    case ARV_BUFFER_STATUS_SIZE_MISMATCH:
      return "image larger than the buffer";
    case ARV_BUFFER_STATUS_FILLING:
      return "still filling";
    case ARV_BUFFER_STATUS_ABORTED:
      return "aborted";
    default:
      return "unknown status";
  }
}

}  // namespace

ArvPixelFormat ArvPixelFormatOf(RawFormat format) {
  switch (format) {
    case RawFormat::kMono8:
      return ARV_PIXEL_FORMAT_MONO_8;
    case RawFormat::kMono16:
      return ARV_PIXEL_FORMAT_MONO_16;
    case RawFormat::kBayerRG8:
      return ARV_PIXEL_FORMAT_BAYER_RG_8;
    case RawFormat::kBayerGR8:
      return ARV_PIXEL_FORMAT_BAYER_GR_8;
    case RawFormat::kBayerGB8:
      return ARV_PIXEL_FORMAT_BAYER_GB_8;
    case RawFormat::kBayerBG8:
      return ARV_PIXEL_FORMAT_BAYER_BG_8;
    case RawFormat::kRGB8:
      return ARV_PIXEL_FORMAT_RGB_8_PACKED;
    case RawFormat::kBGR8:
      return ARV_PIXEL_FORMAT_BGR_8_PACKED;
  }
  return ARV_PIXEL_FORMAT_MONO_8;
}

void AravisOptions::Validate() const {
  const std::string where = "aravis options: ";
  if (!pixel_format.empty() && !RawFormatFromName(pixel_format)) {
    std::string list;
    for (const std::string& n : DecodableFormatNames()) list += (list.empty() ? "" : ", ") + n;
    throw Error(where + "pixel_format '" + pixel_format + "' is not supported (use one of " + list +
                ", or empty for the camera's current format)");
  }
  if (buffers < 2 || buffers > 256) {
    throw Error(where + "buffers = " + std::to_string(buffers) + " must be in 2..256");
  }
  if (!(timeout_s > 0) || timeout_s > 600) {
    throw Error(where + "timeout_s = " + std::to_string(timeout_s) + " must be in (0, 600] s");
  }
  if (retries < 0 || retries > 16) {
    throw Error(where + "retries = " + std::to_string(retries) + " must be in 0..16");
  }
  if (settle_frames < 0 || settle_frames > 16) {
    throw Error(where + "settle_frames = " + std::to_string(settle_frames) + " must be in 0..16");
  }
  if (!(frame_rate >= 0) || frame_rate > 1e5) {
    throw Error(where + "frame_rate = " + std::to_string(frame_rate) +
                " must be 0 (leave) or a positive rate in frames per second");
  }
  if (width < 0 || height < 0 || width > 65535 || height > 65535 ||
      ((width == 0) != (height == 0))) {
    throw Error(where + "region " + std::to_string(width) + "x" + std::to_string(height) +
                " must be both 0 (leave) or both positive");
  }
  if (!(raw_gain_db_per_step > 0) || !std::isfinite(raw_gain_db_per_step)) {
    throw Error(where + "raw_gain_db_per_step must be a positive number of dB");
  }
}

uint64_t MissingFrameIds(uint64_t previous, uint64_t next) {
  if (next > previous) return next - previous - 1;
  if (next == previous) return 0;  // repeated id: nothing lost
  if (previous <= 0xFFFF && next >= 1 && next <= 0xFFFF) {
    // 16-bit block id wrapped: previous+1 .. 65535, then 1 .. next-1 (0 is never used). As in
    // serial-number arithmetic (RFC 1982), a step back of more than half the range is not a
    // wrap but a restarted counter or a late frame (93 -> 1 is not 65,442 frames lost).
    const uint64_t lost = (0xFFFF - previous) + (next - 1);
    if (lost < 0x8000) return lost;
  }
  return 0;  // the counter restarted (camera reset) or a late frame; nothing can be said
}

std::vector<AravisDeviceInfo> ListAravisDevices(bool include_fake) {
  if (include_fake) arv_enable_interface("Fake");
  arv_update_device_list();
  std::vector<AravisDeviceInfo> out;
  const unsigned n = arv_get_n_devices();
  for (unsigned i = 0; i < n; ++i) {
    AravisDeviceInfo d;
    d.id = Str(arv_get_device_id(i));
    d.vendor = Str(arv_get_device_vendor(i));
    d.model = Str(arv_get_device_model(i));
    d.serial = Str(arv_get_device_serial_nbr(i));
    d.protocol = Str(arv_get_device_protocol(i));
    d.address = Str(arv_get_device_address(i));
    if (d.protocol == "Fake" && !include_fake) continue;
    out.push_back(std::move(d));
  }
  return out;
}

std::string AravisCamera::Take(GError*& error) {
  if (error == nullptr) return "";
  const bool timeout =
      (error->domain == ARV_DEVICE_ERROR && (error->code == ARV_DEVICE_ERROR_TIMEOUT ||
                                             error->code == ARV_DEVICE_ERROR_NOT_CONNECTED)) ||
      (error->message && std::string(error->message).find("timeout") != std::string::npos);
  std::string msg = TakeError(error);
  if (timeout && !lost_) {
    lost_ = true;
    lost_reason_ = msg;
  }
  return msg;
}

void AravisCamera::CheckAlive() {
  if (impl_->control_lost.load()) {
    lost_ = true;
    if (lost_reason_.empty()) lost_reason_ = "control channel lost (heartbeat)";
  }
  if (lost_) {
    throw DeviceError(Id() + ": camera not answering (" + lost_reason_ +
                      "); reopen it once it is back");
  }
}

void AravisCamera::Fail(const std::string& what, const std::string& detail) {
  throw DeviceError(Id() + ": " + what + (detail.empty() ? "" : ": " + detail));
}

AravisCamera::AravisCamera(const AravisOptions& options)
    : options_(options), impl_(std::make_unique<Impl>()) {
  options_.Validate();
  GError* err = nullptr;
  Impl& im = *impl_;
  if (options_.enable_fake_interface) arv_enable_interface("Fake");
  // A named device is opened directly (no 1-s discovery round when it is known already).
  if (!options_.device_id.empty()) {
    im.camera = arv_camera_new(options_.device_id.c_str(), &err);
    TakeError(err);
    if (im.camera) device_id_ = options_.device_id;
  }
  if (im.camera == nullptr) {
    // Discover, then match the id or the serial number; the error lists what was seen.
    const std::vector<AravisDeviceInfo> devices = ListAravisDevices(options_.enable_fake_interface);
    const AravisDeviceInfo* found = nullptr;
    for (const AravisDeviceInfo& d : devices) {
      if (options_.device_id.empty() || d.id == options_.device_id ||
          (!d.serial.empty() && d.serial == options_.device_id)) {
        found = &d;
        break;
      }
    }
    if (found == nullptr) {
      std::string seen;
      for (const AravisDeviceInfo& d : devices) seen += (seen.empty() ? "" : ", ") + d.id;
      if (options_.device_id.empty()) {
        throw DeviceError(
            "aravis: no camera found (GigE Vision discovery and USB3 Vision "
            "enumeration saw nothing)");
      }
      throw DeviceError("aravis: no camera '" + options_.device_id +
                        "' (cameras seen: " + (seen.empty() ? "none" : seen) + ")");
    }
    device_id_ = found->id;
    im.camera = arv_camera_new(device_id_.c_str(), &err);
    if (im.camera == nullptr) Fail("cannot open", Take(err));
  }
  im.control_lost_handler = g_signal_connect(arv_camera_get_device(im.camera), "control-lost",
                                             G_CALLBACK(+[](ArvDevice*, gpointer data) {
                                               static_cast<Impl*>(data)->control_lost.store(true);
                                             }),
                                             &im);
  if (arv_camera_is_gv_device(im.camera)) {
    protocol_ = "GigEVision";
  } else if (arv_camera_is_uv_device(im.camera)) {
    protocol_ = "USB3Vision";
  } else if (ARV_IS_FAKE_DEVICE(arv_camera_get_device(im.camera))) {
    protocol_ = "Fake";
  } else {
    protocol_ = "unknown";
  }
  try {
    if (arv_camera_is_gv_device(im.camera)) {
      // As root the packet socket receives nothing on loopback; the socket path works
      // everywhere at the cost of some CPU.
      arv_camera_gv_set_stream_options(im.camera, ARV_GV_STREAM_OPTION_PACKET_SOCKET_DISABLED);
    }
    arv_camera_stop_acquisition(im.camera, &err);
    TakeError(err);  // not acquiring: fine

    // Pixel format.
    guint n_formats = 0;
    const char** names =
        arv_camera_dup_available_pixel_formats_as_strings(im.camera, &n_formats, &err);
    std::vector<std::string> offered;
    for (guint i = 0; names && i < n_formats; ++i) offered.push_back(Str(names[i]));
    g_free(names);
    TakeError(err);
    std::string want = options_.pixel_format;
    if (want.empty()) {
      want = Str(arv_camera_get_pixel_format_as_string(im.camera, &err));
      TakeError(err);
      if (!RawFormatFromName(want)) {
        for (const std::string& o : offered)
          if (RawFormatFromName(o)) {
            want = o;
            break;
          }
      }
    }
    std::string offered_list;
    for (const std::string& o : offered) offered_list += (offered_list.empty() ? "" : ", ") + o;
    if (!RawFormatFromName(want) ||
        (!offered.empty() && std::find(offered.begin(), offered.end(), want) == offered.end())) {
      Fail("pixel format '" + want + "' not available",
           "the camera offers " + (offered_list.empty() ? "nothing readable" : offered_list));
    }
    im.format = *RawFormatFromName(want);
    im.arv_format = ArvPixelFormatOf(im.format);
    pixel_format_ = want;
    arv_camera_set_pixel_format(im.camera, im.arv_format, &err);
    if (err) Fail("cannot set pixel format " + want, Take(err));

    if (options_.width > 0) {
      arv_camera_set_region(im.camera, 0, 0, options_.width, options_.height, &err);
      if (err) Fail("cannot set region", Take(err));
    }

    // Frame rate first: Aravis' arv_camera_set_frame_rate switches the FrameStart trigger off.
    if (options_.frame_rate > 0) {
      const bool fr = arv_camera_is_frame_rate_available(im.camera, &err);
      TakeError(err);
      if (!fr) Fail("frame rate requested", "the camera has no frame rate control");
      arv_camera_set_frame_rate(im.camera, options_.frame_rate, &err);
      if (err) Fail("cannot set the frame rate", Take(err));
    }
    // Trigger.
    const bool sw = arv_camera_is_software_trigger_supported(im.camera, &err);
    TakeError(err);
    if (options_.trigger == AravisTrigger::kSoftware && !sw) {
      Fail("software trigger requested", "the camera has no TriggerSoftware");
    }
    software_trigger_ = options_.trigger == AravisTrigger::kSoftware ||
                        (options_.trigger == AravisTrigger::kAuto && sw);
    arv_camera_set_acquisition_mode(im.camera, ARV_ACQUISITION_MODE_CONTINUOUS, &err);
    if (err) Fail("cannot set continuous acquisition", Take(err));
    if (software_trigger_) {
      arv_camera_set_trigger(im.camera, "Software", &err);
      if (err) Fail("cannot select the software trigger", Take(err));
    } else {
      arv_camera_clear_triggers(im.camera, &err);
      TakeError(err);  // cameras without trigger features free-run anyway
    }

    // Exposure: manual, bounds, current value.
    if (arv_camera_is_exposure_auto_available(im.camera, nullptr)) {
      arv_camera_set_exposure_time_auto(im.camera, ARV_AUTO_OFF, &err);
      TakeError(err);
    }
    if (!arv_camera_is_exposure_time_available(im.camera, &err)) {
      Fail("no exposure control", Take(err));
    }
    double lo = 0, hi = 0;
    arv_camera_get_exposure_time_bounds(im.camera, &lo, &hi, &err);
    if (err || !(lo > 0) || !(hi >= lo)) Fail("cannot read the exposure range", Take(err));
    exposure_min_s_ = lo * 1e-6;
    exposure_max_s_ = hi * 1e-6;
    const double us = arv_camera_get_exposure_time(im.camera, &err);
    if (err) Fail("cannot read the exposure", Take(err));
    exposure_s_ = us * 1e-6;

    // Gain: manual, dB ("Gain", "GainAbs") or raw steps ("GainRaw").
    gain_available_ = arv_camera_is_gain_available(im.camera, &err);
    TakeError(err);
    if (gain_available_) {
      if (arv_camera_is_gain_auto_available(im.camera, nullptr)) {
        arv_camera_set_gain_auto(im.camera, ARV_AUTO_OFF, &err);
        TakeError(err);
      }
      gain_in_db_ = arv_camera_is_feature_available(im.camera, "Gain", nullptr) ||
                    arv_camera_is_feature_available(im.camera, "GainAbs", nullptr);
      double glo = 0, ghi = 0;
      arv_camera_get_gain_bounds(im.camera, &glo, &ghi, &err);
      if (err) Fail("cannot read the gain range", Take(err));
      const double step_db = gain_in_db_ ? 1.0 : options_.raw_gain_db_per_step;
      gain_min_ = std::pow(10.0, glo * step_db / 20);
      gain_max_ = std::pow(10.0, ghi * step_db / 20);
      const double g = arv_camera_get_gain(im.camera, &err);
      if (err) Fail("cannot read the gain", Take(err));
      gain_ = std::pow(10.0, g * step_db / 20);
    }
    StartStream();
  } catch (...) {
    StopStream();
    ReleaseCamera();
    throw;
  }
}

void AravisCamera::ReleaseCamera() {
  if (!impl_ || impl_->camera == nullptr) return;
  if (impl_->control_lost_handler) {
    g_signal_handler_disconnect(arv_camera_get_device(impl_->camera), impl_->control_lost_handler);
    impl_->control_lost_handler = 0;
  }
  g_clear_object(&impl_->camera);
}

AravisCamera::~AravisCamera() {
  if (impl_ && impl_->camera && (lost_ || impl_->control_lost.load())) {
    // The camera stopped answering: Aravis' finalisers still talk to it (stream channel reset,
    // leaving control: about 10 s of control-channel timeouts). Let a background thread
    // finish that so that closing a lost camera does not block the caller.
    if (impl_->control_lost_handler) {
      g_signal_handler_disconnect(arv_camera_get_device(impl_->camera),
                                  impl_->control_lost_handler);
    }
    ArvStream* stream = impl_->stream;
    ArvCamera* camera = impl_->camera;
    impl_->stream = nullptr;
    impl_->camera = nullptr;
    std::thread([stream, camera] {
      if (stream) g_object_unref(stream);
      g_object_unref(camera);
    }).detach();
    return;
  }
  StopStream();
  ReleaseCamera();
}

std::string AravisCamera::Id() const { return "aravis:" + device_id_; }

void AravisCamera::StartStream() {
  Impl& im = *impl_;
  GError* err = nullptr;
  const guint payload = arv_camera_get_payload(im.camera, &err);
  if (err || payload == 0) Fail("cannot read the payload size", Take(err));
  gint x = 0, y = 0;
  arv_camera_get_region(im.camera, &x, &y, &im.width, &im.height, &err);
  if (err || im.width <= 0 || im.height <= 0) Fail("cannot read the region", Take(err));
  const size_t needed = static_cast<size_t>(im.width) * im.height * BytesPerPixel(im.format);
  if (payload < needed) {
    Fail("payload " + std::to_string(payload) + " bytes is smaller than a " +
             std::to_string(im.width) + "x" + std::to_string(im.height) + " " + pixel_format_ +
             " frame",
         "");
  }
  im.payload = payload;
  im.stream = arv_camera_create_stream(im.camera, nullptr, nullptr, &err);
  if (im.stream == nullptr) Fail("cannot create the stream", Take(err));
  if (ARV_IS_GV_STREAM(im.stream)) {
    // Socket buffer sized to the payload, or frames are lost (see NOTES).
    g_object_set(im.stream, "socket-buffer", ARV_GV_STREAM_SOCKET_BUFFER_AUTO, nullptr);
  }
  for (int i = 0; i < options_.buffers; ++i) {
    arv_stream_push_buffer(im.stream, arv_buffer_new_allocate(im.payload));
  }
  arv_camera_start_acquisition(im.camera, &err);
  if (err) {
    const std::string msg = Take(err);
    StopStream();
    Fail("cannot start acquisition", msg);
  }
  have_last_id_ = false;  // a new acquisition may restart the frame counter
  stale_ = true;
  im.restart = false;
}

void AravisCamera::StopStream() {
  if (!impl_ || impl_->stream == nullptr) return;
  GError* err = nullptr;
  if (impl_->camera && !lost_ && !impl_->control_lost.load()) {
    arv_camera_stop_acquisition(impl_->camera, &err);
    TakeError(err);
  }
  // Unreffing the stream stops its thread and frees its buffers.
  g_clear_object(&impl_->stream);
}

void AravisCamera::SetRegion(int width, int height) {
  if (width <= 0 || height <= 0) {
    throw DeviceError(Id() + ": region " + std::to_string(width) + "x" + std::to_string(height) +
                      " must be positive");
  }
  CheckAlive();
  Impl& im = *impl_;
  if (im.stream && width == im.width && height == im.height) return;
  StopStream();
  GError* err = nullptr;
  arv_camera_set_region(im.camera, 0, 0, width, height, &err);
  if (err)
    Fail("cannot set region " + std::to_string(width) + "x" + std::to_string(height), Take(err));
  StartStream();
  if (im.width != width || im.height != height) {
    Fail("region " + std::to_string(width) + "x" + std::to_string(height) + " not applied",
         "the camera holds " + std::to_string(im.width) + "x" + std::to_string(im.height));
  }
}

std::vector<ControlInfo> AravisCamera::Controls() const {
  return {{"exposure_s", exposure_min_s_, exposure_max_s_, exposure_s_},
          {"gain", gain_min_, gain_max_, gain_},
          {"nd_density", 0.0, 10.0, nd_}};
}

double AravisCamera::SetExposure(double seconds) {
  if (!(seconds > 0) || !std::isfinite(seconds)) {
    throw DeviceError(Id() + ": exposure " + std::to_string(seconds) + " s is not positive");
  }
  CheckAlive();
  Impl& im = *impl_;
  GError* err = nullptr;
  const double us = std::clamp(seconds * 1e6, exposure_min_s_ * 1e6, exposure_max_s_ * 1e6);
  arv_camera_set_exposure_time(im.camera, us, &err);
  if (err) Fail("cannot set exposure " + std::to_string(us) + " us", Take(err));
  const double back = arv_camera_get_exposure_time(im.camera, &err);
  if (err || !(back > 0) || !std::isfinite(back)) Fail("cannot read back the exposure", Take(err));
  if (back * 1e-6 != exposure_s_) stale_ = true;
  exposure_s_ = back * 1e-6;
  return exposure_s_;
}

double AravisCamera::SetGain(double gain) {
  if (!(gain > 0) || !std::isfinite(gain)) {
    throw DeviceError(Id() + ": gain " + std::to_string(gain) + " must be positive");
  }
  if (!gain_available_) return gain_;  // no gain control: the sensor's fixed gain (1)
  CheckAlive();
  Impl& im = *impl_;
  GError* err = nullptr;
  const double step_db = gain_in_db_ ? 1.0 : options_.raw_gain_db_per_step;
  double lo = 0, hi = 0;
  arv_camera_get_gain_bounds(im.camera, &lo, &hi, &err);
  if (err) Fail("cannot read the gain range", Take(err));
  double value = 20 * std::log10(gain) / step_db;
  if (!gain_in_db_) value = std::round(value);
  value = std::clamp(value, lo, hi);
  arv_camera_set_gain(im.camera, value, &err);
  if (err) Fail("cannot set gain " + std::to_string(value), Take(err));
  const double back = arv_camera_get_gain(im.camera, &err);
  if (err || !std::isfinite(back)) Fail("cannot read back the gain", Take(err));
  const double linear = std::pow(10.0, back * step_db / 20);
  if (linear != gain_) stale_ = true;
  gain_ = linear;
  return gain_;
}

void AravisCamera::SetNdFilter(double density) {
  if (!(density >= 0) || !std::isfinite(density)) {
    throw DeviceError(Id() + ": ND density " + std::to_string(density) + " must be >= 0");
  }
  nd_ = density;
}

CapturedFrame AravisCamera::Grab() {
  CheckAlive();
  Impl& im = *impl_;
  if (im.restart || im.stream == nullptr) {
    StopStream();
    StartStream();
  }
  GError* err = nullptr;
  const guint64 timeout_us = static_cast<guint64>((exposure_s_ + options_.timeout_s) * 1e6);
  auto note_id = [&](ArvBuffer* b) {
    const uint64_t id = arv_buffer_get_frame_id(b);
    if (have_last_id_) stats_.dropped += MissingFrameIds(last_id_, id);
    last_id_ = id;
    have_last_id_ = true;
    stats_.last_frame_id = id;
  };
  auto wait = [&](const char* why) -> ArvBuffer* {
    ArvBuffer* b = arv_stream_timeout_pop_buffer(im.stream, timeout_us);
    if (b == nullptr) {
      ++stats_.timeouts;
      stale_ = true;
      im.restart = software_trigger_;  // the triggered frame may still arrive later
      Fail(std::string("no frame within ") + std::to_string(exposure_s_ + options_.timeout_s) +
               " s (" + why + ")",
           "camera gone, cable or network problem, or the exposure exceeds the timeout");
    }
    return b;
  };

  if (stale_) {
    // Buffers already delivered were exposed before the change: give them back unread.
    while (ArvBuffer* b = arv_stream_try_pop_buffer(im.stream)) {
      note_id(b);
      ++stats_.discarded;
      arv_stream_push_buffer(im.stream, b);
    }
    // Free-running, the camera keeps sending while nobody grabs and frames find no free
    // buffer: that is not a transport loss, so the id baseline restarts here.
    if (!software_trigger_) have_last_id_ = false;
  }
  if (software_trigger_) {
    arv_camera_software_trigger(im.camera, &err);
    if (err) Fail("software trigger failed", Take(err));
  } else if (stale_) {
    // Frames the camera was exposing or reading out while the change arrived.
    for (int i = 0; i < options_.settle_frames; ++i) {
      ArvBuffer* b = wait("discarding frames in flight");
      note_id(b);
      ++stats_.discarded;
      arv_stream_push_buffer(im.stream, b);
    }
  }
  ArvBuffer* b = wait("waiting for the frame");
  note_id(b);
  stale_ = false;
  // An incomplete frame (lost packets the resend could not recover) is grabbed again, up to
  // `retries` times: triggered again, or the next free-running frame.
  for (int attempt = 0;; ++attempt) {
    const ArvBufferStatus status = arv_buffer_get_status(b);
    if (status == ARV_BUFFER_STATUS_SUCCESS) break;
    ++stats_.incomplete;
    const std::string what = "incomplete frame " + std::to_string(arv_buffer_get_frame_id(b));
    arv_stream_push_buffer(im.stream, b);
    if (attempt >= options_.retries) {
      stale_ = true;
      Fail(what + " (after " + std::to_string(attempt) + " retries)", StatusName(status));
    }
    if (software_trigger_) {
      arv_camera_software_trigger(im.camera, &err);
      if (err) Fail("software trigger failed", Take(err));
    }
    b = wait("waiting for a frame to replace an incomplete one");
    note_id(b);
  }
  // From here on the buffer goes back to the stream whatever happens.
  struct Return {
    ArvStream* s;
    ArvBuffer* b;
    ~Return() { arv_stream_push_buffer(s, b); }
  } give_back{im.stream, b};
  const ArvBufferPayloadType type = arv_buffer_get_payload_type(b);
  if (type != ARV_BUFFER_PAYLOAD_TYPE_IMAGE &&
      type != ARV_BUFFER_PAYLOAD_TYPE_EXTENDED_CHUNK_DATA &&
      type != ARV_BUFFER_PAYLOAD_TYPE_CHUNK_DATA) {
    ++stats_.incomplete;
    Fail("frame " + std::to_string(arv_buffer_get_frame_id(b)) + " carries no image",
         "payload type " + std::to_string(static_cast<int>(type)));
  }
  const ArvPixelFormat pf = arv_buffer_get_image_pixel_format(b);
  if (pf != im.arv_format) {
    ++stats_.incomplete;
    Fail("frame in pixel format 0x" + std::to_string(pf) + ", expected " + pixel_format_, "");
  }
  const int w = arv_buffer_get_image_width(b), h = arv_buffer_get_image_height(b);
  const size_t needed =
      static_cast<size_t>(std::max(w, 0)) * std::max(h, 0) * BytesPerPixel(im.format);
  if (w <= 0 || h <= 0 || needed > im.payload) {
    ++stats_.incomplete;
    Fail("frame size " + std::to_string(w) + "x" + std::to_string(h) + " does not fit the " +
             std::to_string(im.payload) + "-byte buffer",
         "");
  }
  size_t size = 0;
  const auto* data = static_cast<const uint8_t*>(arv_buffer_get_image_data(b, &size));
  if (size == 0 && protocol_ == "Fake") {
    // Aravis 0.8.26: a custom fill pattern of the in-process Fake camera leaves the received
    // size at 0; the buffer holds `payload` bytes we allocated.
    data = static_cast<const uint8_t*>(arv_buffer_get_data(b, nullptr));
    size = im.payload;
  }
  if (data == nullptr || size < needed) {
    ++stats_.incomplete;
    Fail("short frame " + std::to_string(arv_buffer_get_frame_id(b)),
         std::to_string(size) + " of " + std::to_string(needed) + " bytes");
  }
  CapturedFrame f;
  f.image = DecodeFrame(data, size, w, h, im.format);
  f.hdr = false;
  f.exposure_s = exposure_s_;
  f.gain = gain_;
  f.nd_density = nd_;
  const guint64 sys_ns = arv_buffer_get_system_timestamp(b);
  const int64_t end_ns = sys_ns > 0 ? static_cast<int64_t>(sys_ns) : NowUtc().ns;
  f.utc.ns = end_ns - std::llround(exposure_s_ * 0.5e9);
  ++stats_.delivered;
  return f;
}

std::unique_ptr<Camera> OpenAravisCamera(const AravisOptions& options) {
  return std::make_unique<AravisCamera>(options);
}

}  // namespace rouen
