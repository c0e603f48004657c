#include "core/trees.h"

#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <utility>

#include "core/angles.h"
#include "core/error.h"
#include "core/text.h"

namespace rouen {

void TreeMeshOptions::Validate() const {
  if (!(trunk_diameter_m >= 0) || !std::isfinite(trunk_diameter_m))
    throw Error("trees: trunk_diameter_m must be a finite length >= 0");
  if (crown_segments < 3 || crown_segments > 256 || crown_rings < 2 || crown_rings > 256 ||
      trunk_segments < 3 || trunk_segments > 256)
    throw Error(
        "trees: crown_segments and trunk_segments must be in 3..256, crown_rings in 2..256");
}

namespace {

enum Column { kName, kX, kY, kHeight, kCrownDiameter, kCrownDepth, kTrunkDiameter, kBaseZ, kCount };
constexpr const char* kColumnNames[kCount] = {
    "name",    "x_m", "y_m", "height_m", "crown_diameter_m", "crown_depth_m", "trunk_diameter_m",
    "base_z_m"};

bool IsWord(const std::string& s) {
  if (s.empty()) return false;
  for (char c : s) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '-' || c == '.';
    if (!ok) return false;
  }
  return true;
}

// The trees of a CSV file's lines (ParseTrees).
std::vector<Tree> TreesOfLines(const std::vector<std::string>& lines, const std::string& name,
                               const TreeMeshOptions& options) {
  options.Validate();
  std::vector<int> column_of;  // CSV field -> Column
  std::vector<Tree> trees;
  std::map<std::string, int> line_of_name;
  int line_number = 0;
  for (const std::string& text : lines) {
    const std::string line = Trimmed(text);
    ++line_number;
    const std::string where = name + ":" + std::to_string(line_number);
    if (line.empty() || line.front() == '#') continue;
    const std::vector<std::string> fields = CsvFields(line);
    if (column_of.empty()) {  // the header
      std::set<int> seen;
      for (const std::string& f : fields) {
        int c = 0;
        while (c < kCount && f != kColumnNames[c]) ++c;
        if (c == kCount)
          throw Error(where + ": unknown column '" + f +
                      "' (the header names name, x_m, y_m, height_m, crown_diameter_m and "
                      "optionally crown_depth_m, trunk_diameter_m, base_z_m)");
        if (!seen.insert(c).second) throw Error(where + ": column '" + f + "' given twice");
        column_of.push_back(c);
      }
      for (int c : {kX, kY, kHeight, kCrownDiameter}) {
        if (!seen.count(c))
          throw Error(where + ": the header has no column '" + kColumnNames[c] + "'");
      }
      continue;
    }
    if (fields.size() != column_of.size())
      throw Error(where + ": " + std::to_string(fields.size()) + " fields, the header has " +
                  std::to_string(column_of.size()));
    std::optional<double> value[kCount];
    Tree tree;
    tree.name = "tree_" + std::to_string(line_number);
    for (size_t i = 0; i < fields.size(); ++i) {
      const int c = column_of[i];
      if (c == kName) {
        if (!IsWord(fields[i]))
          throw Error(where + ": name '" + fields[i] +
                      "' is not one word of letters, digits, '_', '-' or '.'");
        tree.name = fields[i];
        continue;
      }
      double v = 0;
      if (!ParseDecimal(fields[i], &v))
        throw Error(where + ": " + kColumnNames[c] + " '" + fields[i] + "' is not a number");
      value[c] = v;
    }
    tree.position = {*value[kX], *value[kY]};
    tree.height_m = *value[kHeight];
    tree.crown_diameter_m = *value[kCrownDiameter];
    tree.crown_depth_m = value[kCrownDepth].value_or(tree.crown_diameter_m);
    tree.trunk_diameter_m = value[kTrunkDiameter].value_or(options.trunk_diameter_m);
    tree.base_z_m = value[kBaseZ].value_or(0.0);
    for (const auto& [v, c] :
         {std::pair{tree.height_m, kHeight}, std::pair{tree.crown_diameter_m, kCrownDiameter},
          std::pair{tree.crown_depth_m, kCrownDepth}}) {
      if (!(v > 0)) throw Error(where + ": " + kColumnNames[c] + " must be positive");
    }
    if (tree.crown_depth_m > tree.height_m)
      throw Error(where + Formatted(": the crown (crown_depth_m %g m) is deeper than the tree is "
                                    "high (height_m %g m)",
                                    tree.crown_depth_m, tree.height_m));
    if (!(tree.trunk_diameter_m >= 0) || tree.trunk_diameter_m >= tree.crown_diameter_m)
      throw Error(where + ": trunk_diameter_m must be >= 0 and less than crown_diameter_m");
    const auto [it, added] = line_of_name.emplace(tree.name, line_number);
    if (!added)
      throw Error(where + ": the name '" + tree.name + "' is line " + std::to_string(it->second) +
                  "'s too");
    trees.push_back(tree);
  }
  if (column_of.empty()) throw Error(name + ": no header and no trees");
  if (trees.empty()) throw Error(name + ": a header and no trees");
  return trees;
}

}  // namespace

std::vector<Tree> ParseTrees(std::string_view text, const std::string& name,
                             const TreeMeshOptions& options) {
  return TreesOfLines(TextLines(text), name, options);
}

std::vector<Tree> ReadTrees(const std::string& path, const TreeMeshOptions& options) {
  return TreesOfLines(ReadTextLines(path, "a trees CSV"), path, options);
}

std::string TreesObjText(const std::vector<Tree>& trees, const TreeMeshOptions& options) {
  options.Validate();
  std::string out = "# trees: a crown (an ellipsoid) on a trunk (a cylinder) per tree\n";
  for (const Tree& t : trees) {
    const double a = t.crown_diameter_m / 2, c = t.crown_depth_m / 2;
    const double zc = t.base_z_m + t.height_m - c;
    const double x = t.position.x(), y = t.position.y();
    std::vector<Eigen::Vector3d> v;
    std::vector<std::vector<int>> faces;  // 0-based within this tree
    const int S = options.crown_segments, R = options.crown_rings;
    v.emplace_back(x, y, zc + c);
    for (int i = 1; i < R; ++i) {
      const double th = kPi * i / R;
      for (int j = 0; j < S; ++j) {
        const double ph = 2 * kPi * j / S;
        v.emplace_back(x + a * std::sin(th) * std::cos(ph), y + a * std::sin(th) * std::sin(ph),
                       zc + c * std::cos(th));
      }
    }
    v.emplace_back(x, y, zc - c);
    const int bottom = static_cast<int>(v.size()) - 1;
    const auto ring = [&](int i, int j) { return 1 + (i - 1) * S + j % S; };
    for (int j = 0; j < S; ++j) faces.push_back({0, ring(1, j), ring(1, j + 1)});
    for (int i = 1; i + 1 < R; ++i) {
      for (int j = 0; j < S; ++j)
        faces.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
    for (int j = 0; j < S; ++j) faces.push_back({ring(R - 1, j), bottom, ring(R - 1, j + 1)});
    // The trunk rises from the ground to where the crown is as wide as it is (a crown down to
    // the ground, a bush, has none).
    const double rt = t.trunk_diameter_m / 2;
    const double top = zc - c * std::sqrt(std::max(0.0, 1 - (rt / a) * (rt / a)));
    if (rt > 0 && zc - c > t.base_z_m) {
      const int first = static_cast<int>(v.size()), T = options.trunk_segments;
      for (int j = 0; j < T; ++j) {
        const double ph = 2 * kPi * j / T;
        v.emplace_back(x + rt * std::cos(ph), y + rt * std::sin(ph), t.base_z_m);
        v.emplace_back(x + rt * std::cos(ph), y + rt * std::sin(ph), top);
      }
      for (int j = 0; j < T; ++j) {
        const int p = first + 2 * j, q = first + 2 * ((j + 1) % T);
        faces.push_back({p, q, q + 1, p + 1});
      }
    }
    out += "g " + t.name + "\n";
    for (const Eigen::Vector3d& p : v) out += Formatted("v %.6f %.6f %.6f\n", p.x(), p.y(), p.z());
    const int n = static_cast<int>(v.size());
    for (const auto& f : faces) {
      out += "f";
      for (int k : f) out.append(" ").append(std::to_string(k - n));
      out += "\n";
    }
  }
  return out;
}

}  // namespace rouen
