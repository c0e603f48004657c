#include "core/memory.h"

#include <gtest/gtest.h>

#include <string>

#include "core/error.h"

namespace rouen {
namespace {

// The figure is the kernel's: positive on Linux, and a need far beyond it is refused with both
// figures and the advice; a need within it passes.
TEST(MemoryTest, ANeedBeyondWhatIsAvailableIsRefusedWithItsFigures) {
  const int64_t available = AvailableMemoryBytes();
  ASSERT_GT(available, 0);
  EXPECT_NO_THROW(CheckMemory(available / 4, "a small image", "smaller"));
  try {
    CheckMemory(available * 4 + (int64_t{1} << 30), "render: a 1000000x1000000 image",
                "a smaller --size");
    ADD_FAILURE() << "accepted";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind("render: a 1000000x1000000 image needs about ", 0), 0u) << m;
    EXPECT_NE(m.find(" GB are available (a smaller --size)"), std::string::npos) << m;
  }
}

}  // namespace
}  // namespace rouen
