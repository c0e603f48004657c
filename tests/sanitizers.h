// Whether this test binary was built with AddressSanitizer (./dev test --sanitize): tests
// that repeat a path hundreds of times sample it, and throughput measurements skip, there.
#pragma once

namespace rouen::testing_build {

#if defined(__SANITIZE_ADDRESS__)  // gcc
constexpr bool kSanitized = true;
#elif defined(__has_feature)  // clang
#if __has_feature(address_sanitizer)
constexpr bool kSanitized = true;
#else
constexpr bool kSanitized = false;
#endif
#else
constexpr bool kSanitized = false;
#endif

}  // namespace rouen::testing_build
