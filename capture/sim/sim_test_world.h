// Test helper: one quick simulated world per test process, lit at a fixed afternoon time.
#pragma once

#include "capture/sim/sim_world.h"
#include "core/time.h"

namespace rouen {

// 2026-08-25 13:30 PDT: sun ~62 deg high, azimuth ~190 deg.
inline UtcTime SimTestNoon() { return ParseIso8601("2026-08-25T13:30:00-07:00"); }
inline UtcTime SimTestEvening() { return ParseIso8601("2026-08-25T18:15:00-07:00"); }

inline SimWorld& SimTestWorld() {
  static SimWorld* world = [] {
    SimWorldOptions o;
    o.quick = true;
    auto* w = new SimWorld(o);
    w->SetTime(SimTestNoon());
    return w;
  }();
  return *world;
}

}  // namespace rouen
