// Named figures a benchmark records for bench/run, which collects them into
// bench/results.json. A figure is written only when ROUEN_BENCH_RESULTS names a JSON file; each
// Record() merges one figure into it (read, update, write a temporary, rename), so several
// benchmark binaries can fill one file in turn and a crash leaves the last whole version.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace rouen::bench {

// Figure `name` ("merge.memorial.x_opencv": dot-separated, lower case) = `value` in `unit`;
// `peer` names what a ratio is measured against in the same run (empty when it is no ratio).
inline void Record(const std::string& name, double value, const std::string& unit,
                   const std::string& peer = "") {
  const char* path = std::getenv("ROUEN_BENCH_RESULTS");
  if (path == nullptr || *path == '\0') return;
  nlohmann::json all = nlohmann::json::object();
  if (std::ifstream in(path); in) {
    all = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
    if (!all.is_object()) all = nlohmann::json::object();
  }
  nlohmann::json figure = {{"value", value}, {"unit", unit}};
  if (!peer.empty()) figure["peer"] = peer;
  all[name] = figure;
  const std::string tmp = std::string(path) + ".tmp";
  {
    std::ofstream out(tmp);
    out << all.dump(2) << "\n";
    if (!out) {
      std::fprintf(stderr, "bench: cannot write %s\n", tmp.c_str());
      return;
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) std::fprintf(stderr, "bench: cannot rename %s: %s\n", tmp.c_str(), ec.message().c_str());
}

}  // namespace rouen::bench
