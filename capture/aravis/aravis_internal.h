// Aravis objects behind AravisCamera, for the files of this folder only (includes <arv.h>).
#pragma once

#include <arv.h>

#include <atomic>
#include <cstddef>

#include "capture/aravis/aravis_camera.h"
#include "capture/aravis/pixel_decode.h"

namespace rouen {

struct AravisCamera::Impl {
  ArvCamera* camera = nullptr;
  ArvStream* stream = nullptr;
  size_t payload = 0;  // bytes per buffer
  RawFormat format = RawFormat::kMono8;
  ArvPixelFormat arv_format = 0;
  int width = 0, height = 0;
  bool restart = false;  // a triggered frame may still be in flight: restart the stream
  gulong control_lost_handler = 0;
  std::atomic<bool> control_lost{false};  // set by the device's heartbeat thread
};

// The ArvPixelFormat code of a decodable format.
ArvPixelFormat ArvPixelFormatOf(RawFormat format);

}  // namespace rouen
