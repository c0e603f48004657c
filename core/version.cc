#include "core/version.h"

namespace rouen {

const char* RouenVersion() { return ROUEN_VERSION; }

}  // namespace rouen
