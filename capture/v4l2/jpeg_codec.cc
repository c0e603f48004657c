#include "capture/v4l2/jpeg_codec.h"

#ifdef ROUEN_HAVE_JPEG
#include <csetjmp>
#include <cstdio>
#include <cstdlib>
// jpeglib.h needs size_t and FILE declared first.
#include <jerror.h>
#include <jpeglib.h>
#endif

namespace rouen::v4l2_internal {

#ifdef ROUEN_HAVE_JPEG

namespace {

// libjpeg reports fatal errors through error_exit, which must not return: jump back to the
// caller's setjmp. Nothing with a destructor lives between setjmp and the libjpeg calls.
struct ErrorManager {
  jpeg_error_mgr pub;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
  int damaging_warnings;  // warnings that mean wrong pixels (see EmitMessage)
};

void ErrorExit(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}

void OutputMessage(j_common_ptr) {}  // libjpeg would print to stderr

// Warnings: truncated data and damaged entropy-coded segments leave wrong pixels (libjpeg
// fills the rest with grey); extraneous bytes between markers, which some webcams emit on
// every frame, are harmless and tolerated.
void EmitMessage(j_common_ptr cinfo, int level) {
  if (level >= 0) return;  // trace messages
  auto* err = reinterpret_cast<ErrorManager*>(cinfo->err);
  ++cinfo->err->num_warnings;
  const int code = cinfo->err->msg_code;
  if (code == JWRN_JPEG_EOF || code == JWRN_HIT_MARKER || code == JWRN_MUST_RESYNC ||
      code == JWRN_HUFF_BAD_CODE || code == JWRN_NOT_SEQUENTIAL) {
    if (err->damaging_warnings++ == 0) (*cinfo->err->format_message)(cinfo, err->message);
  }
}

// The decoding steps that may longjmp; returns false on a libjpeg error, or with `*w` x `*h`
// set and nothing allocated when the header's size is not `width` x `height`.
bool DecodeRaw(jpeg_decompress_struct* cinfo, ErrorManager* err, const uint8_t* data, size_t size,
               int width, int height, std::vector<uint8_t>* rgb, int* w, int* h) {
  if (setjmp(err->jump)) return false;
  jpeg_create_decompress(cinfo);
  jpeg_mem_src(cinfo, data, static_cast<unsigned long>(size));
  jpeg_read_header(cinfo, TRUE);
  // A damaged header can claim up to 65500 x 65500: compare before decoding allocates.
  *w = static_cast<int>(cinfo->image_width);
  *h = static_cast<int>(cinfo->image_height);
  if (*w != width || *h != height) return true;
  cinfo->out_color_space = JCS_RGB;
  jpeg_start_decompress(cinfo);
  *w = static_cast<int>(cinfo->output_width);
  *h = static_cast<int>(cinfo->output_height);
  if (cinfo->output_components != 3) {
    std::snprintf(err->message, sizeof(err->message), "JPEG has %d components, not 3",
                  cinfo->output_components);
    return false;
  }
  rgb->resize(static_cast<size_t>(*w) * *h * 3);
  while (cinfo->output_scanline < cinfo->output_height) {
    JSAMPROW row = rgb->data() + static_cast<size_t>(cinfo->output_scanline) * *w * 3;
    jpeg_read_scanlines(cinfo, &row, 1);
  }
  jpeg_finish_decompress(cinfo);
  return true;
}

bool EncodeRaw(jpeg_compress_struct* cinfo, ErrorManager* err, const uint8_t* rgb, int width,
               int height, int quality, bool omit_huffman, unsigned char** out,
               unsigned long* out_size) {
  if (setjmp(err->jump)) return false;
  jpeg_create_compress(cinfo);
  jpeg_mem_dest(cinfo, out, out_size);
  cinfo->image_width = static_cast<JDIMENSION>(width);
  cinfo->image_height = static_cast<JDIMENSION>(height);
  cinfo->input_components = 3;
  cinfo->in_color_space = JCS_RGB;
  jpeg_set_defaults(cinfo);
  jpeg_set_quality(cinfo, quality, TRUE);
  cinfo->comp_info[0].h_samp_factor = 2;  // 4:2:2
  cinfo->comp_info[0].v_samp_factor = 1;
  jpeg_start_compress(cinfo, TRUE);
  if (omit_huffman) {
    // Huffman tables are emitted by the first scan's header, after start_compress; marking
    // them sent leaves the DHT segment out (the decoder then uses the standard tables).
    for (int i = 0; i < NUM_HUFF_TBLS; ++i) {
      if (cinfo->dc_huff_tbl_ptrs[i]) cinfo->dc_huff_tbl_ptrs[i]->sent_table = TRUE;
      if (cinfo->ac_huff_tbl_ptrs[i]) cinfo->ac_huff_tbl_ptrs[i]->sent_table = TRUE;
    }
  }
  while (cinfo->next_scanline < cinfo->image_height) {
    JSAMPROW row =
        const_cast<uint8_t*>(rgb) + static_cast<size_t>(cinfo->next_scanline) * width * 3;
    jpeg_write_scanlines(cinfo, &row, 1);
  }
  jpeg_finish_compress(cinfo);
  return true;
}

}  // namespace

bool JpegAvailable() { return true; }

bool DecodeJpeg(const uint8_t* data, size_t size, int width, int height, Image* out,
                std::string* error) {
  if (size < 4 || data[0] != 0xFF || data[1] != 0xD8) {
    *error = "not a JPEG (no SOI marker)";
    return false;
  }
  jpeg_decompress_struct cinfo{};
  ErrorManager err{};
  cinfo.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = ErrorExit;
  err.pub.output_message = OutputMessage;
  err.pub.emit_message = EmitMessage;
  std::vector<uint8_t> rgb;
  int w = 0, h = 0;
  const bool ok = DecodeRaw(&cinfo, &err, data, size, width, height, &rgb, &w, &h);
  const int damaging = err.damaging_warnings;
  jpeg_destroy_decompress(&cinfo);
  if (!ok) {
    *error = std::string("corrupt JPEG: ") + err.message;
    return false;
  }
  if (damaging > 0) {
    *error = std::string("corrupt JPEG: ") + err.message;
    return false;
  }
  if (w != width || h != height) {
    *error = "JPEG is " + std::to_string(w) + "x" + std::to_string(h) + ", expected " +
             std::to_string(width) + "x" + std::to_string(height);
    return false;
  }
  *out = Image(w, h, 3, PixelUnits::kDigital);
  for (size_t i = 0; i < rgb.size(); ++i) out->data[i] = rgb[i];
  return true;
}

std::vector<uint8_t> EncodeJpeg(const uint8_t* rgb, int width, int height, int quality,
                                bool omit_huffman_tables) {
  jpeg_compress_struct cinfo{};
  ErrorManager err{};
  cinfo.err = jpeg_std_error(&err.pub);
  err.pub.error_exit = ErrorExit;
  err.pub.output_message = OutputMessage;
  unsigned char* buffer = nullptr;
  unsigned long size = 0;
  const bool ok =
      EncodeRaw(&cinfo, &err, rgb, width, height, quality, omit_huffman_tables, &buffer, &size);
  jpeg_destroy_compress(&cinfo);
  std::vector<uint8_t> out;
  if (ok && buffer) out.assign(buffer, buffer + size);
  std::free(buffer);
  return out;
}

#else  // !ROUEN_HAVE_JPEG

bool JpegAvailable() { return false; }

bool DecodeJpeg(const uint8_t*, size_t, int, int, Image*, std::string* error) {
  *error = "MJPEG decoding not built (libjpeg-turbo missing at configure time)";
  return false;
}

std::vector<uint8_t> EncodeJpeg(const uint8_t*, int, int, int, bool) { return {}; }

#endif

}  // namespace rouen::v4l2_internal
