// Wavefront OBJ (core/mesh.h ParseObj). An accepted mesh has finite vertices, every
// triangle's indices and block in range, and no degenerate triangle.
#include <cmath>
#include <string>

#include "core/mesh.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace rouen;
  Mesh mesh;
  if (!fuzz::Accepts([&] { mesh = ParseObj(fuzz::Text(data, size), "fuzz.obj"); }, "fuzz.obj"))
    return 0;
  const int n = static_cast<int>(mesh.vertices.size());
  for (const auto& v : mesh.vertices) FUZZ_CHECK(v.allFinite(), "non-finite vertex");
  FUZZ_CHECK(mesh.triangle_block.size() == mesh.triangles.size(), "one block per triangle");
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      const int i = mesh.triangles[t][k];
      FUZZ_CHECK(i >= 0 && i < n, "index " + std::to_string(i) + " of " + std::to_string(n));
    }
    const int b = mesh.triangle_block[t];
    FUZZ_CHECK(b >= 0 && b < static_cast<int>(mesh.block_names.size()), "block index");
    const double area = mesh.Area(static_cast<int>(t));
    FUZZ_CHECK(std::isfinite(area) && area > 0, "degenerate triangle accepted");
    FUZZ_CHECK(mesh.Normal(static_cast<int>(t)).allFinite(), "non-finite normal");
  }
  return 0;
}
