// Memory known before work: what a step will need, against what the machine has free, so that
// a size inside the documented ranges fails at once with its figures instead of std::bad_alloc
// minutes later.
#pragma once

#include <cstdint>
#include <string>

namespace rouen {

// The memory the kernel says is available to a new allocation (/proc/meminfo's MemAvailable),
// bytes; -1 when it cannot tell.
int64_t AvailableMemoryBytes();

// Throws rouen::Error "<what> needs about X GB of memory; Y GB are available (<advice>)" when
// `bytes` exceeds what is available (nothing when that is unknown).
void CheckMemory(int64_t bytes, const std::string& what, const std::string& advice);

}  // namespace rouen
