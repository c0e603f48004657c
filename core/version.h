// rouen's version (CMakeLists.txt's project version), recorded in what rouen writes.
#pragma once

namespace rouen {

const char* RouenVersion();

}  // namespace rouen
