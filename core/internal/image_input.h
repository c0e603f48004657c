// Internal to rouen_core: reading the pixels of a file opened with OpenImageIO a band of rows
// at a time (ReadImage, ReadRawLinear), so memory follows the rows actually decoded.
#pragma once

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cstddef>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace rouen::internal {

// Opens an image file with the one OpenImageIO reader of its format, picked from its name
// (camera RAW: IsRawFileName; Targa) or its magic number (OpenEXR, PNG, TIFF, JPEG, Radiance
// HDR, BMP, PNM/PFM); `config` as OpenImageIO's open takes it. Before that, checks what the
// readers would trust blindly: in an OpenEXR header, attribute sizes (OpenEXR 3.1 allocates and
// clears a claimed size of up to 2 GB before reading it; a 700-byte file took 1.9 GB and 10 s)
// and channel pixel types (OpenImageIO 2.4 aborts the process on an unknown one); in a PNG,
// chunk lengths (libpng allocates a chunk's claimed length first: a 558-byte file asked for
// 1.7 GB). Throws rouen::Error "PATH: cannot read WHAT: why" for another format, a file that
// cannot be read, or one its reader refuses.
std::unique_ptr<OIIO::ImageInput> OpenImageFile(const std::string& path, const char* what,
                                                const OIIO::ImageSpec* config = nullptr);

// Samples (pixels x channels) per band; a band is at least one row (or one row of tiles).
constexpr size_t kBandSamples = size_t{1} << 22;

// Reads every pixel of the open subimage (a 2D image: depth 1) as `type`, all channels
// interleaved, and calls `band(first_row, rows, data)` for each band of whole rows, top to
// bottom (row 0 = the top of the data window). Returns false when OpenImageIO fails
// (in.geterror() says why); exceptions from `band` propagate.
bool ReadRowBands(OIIO::ImageInput& in, OIIO::TypeDesc type,
                  const std::function<void(int first_row, int rows, const void* data)>& band);

// Resizes `v` to `size` entries (a band more), growing its capacity geometrically but never
// beyond `total` (the size it ends at), so the finished image holds no slack.
inline void GrowTo(std::vector<float>* v, size_t size, size_t total) {
  if (size > v->capacity()) v->reserve(std::min(total, std::max(size, 2 * v->capacity())));
  v->resize(size);
}

}  // namespace rouen::internal
