#include "core/mesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cassert>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <map>
#include <sstream>

#include "core/error.h"
#include "core/files.h"
#include "core/limits.h"
#include "core/text.h"

namespace rouen {
namespace {

// Twice the area of a triangle relative to its longest squared edge below this is degenerate.
constexpr double kDegenerateRatio = 1e-12;

bool IsDegenerate(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const double cross = (b - a).cross(c - a).norm();
  const double longest =
      std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
  return !(cross > kDegenerateRatio * longest) || !(longest > 0);
}

std::vector<std::string_view> Tokens(std::string_view line) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    size_t j = i;
    while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') ++j;
    if (j > i) out.push_back(line.substr(i, j - i));
    i = j;
  }
  return out;
}

bool ParseDouble(std::string_view s, double* v) {
  // std::from_chars for double is available in GCC 11+.
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size() && std::isfinite(*v);
}

bool ParseInt(std::string_view s, long* v) {
  const auto r = std::from_chars(s.data(), s.data() + s.size(), *v);
  return r.ec == std::errc() && r.ptr == s.data() + s.size();
}

}  // namespace

Eigen::Vector3d Mesh::Normal(int t) const {
  const Eigen::Vector3i& tri = triangles[t];
  const Eigen::Vector3d& a = vertices[tri[0]];
  return (vertices[tri[1]] - a).cross(vertices[tri[2]] - a).normalized();
}

double Mesh::Area(int t) const {
  const Eigen::Vector3i& tri = triangles[t];
  const Eigen::Vector3d& a = vertices[tri[0]];
  return 0.5 * (vertices[tri[1]] - a).cross(vertices[tri[2]] - a).norm();
}

void Mesh::Append(const Mesh& other) {
  for (const std::string& name : other.block_names) {
    if (std::find(block_names.begin(), block_names.end(), name) != block_names.end())
      throw Error("block '" + name + "' is in both models (rename the group in one of them)");
  }
  const int v0 = static_cast<int>(vertices.size()), b0 = static_cast<int>(block_names.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  block_names.insert(block_names.end(), other.block_names.begin(), other.block_names.end());
  for (size_t t = 0; t < other.triangles.size(); ++t) {
    triangles.push_back(other.triangles[t] + Eigen::Vector3i::Constant(v0));
    triangle_block.push_back(other.triangle_block[t] + b0);
  }
}

int Mesh::AddBlock(const std::string& name) {
  block_names.push_back(name);
  return static_cast<int>(block_names.size()) - 1;
}

void Mesh::AddTriangle(int a, int b, int c, int block) {
  assert(a >= 0 && b >= 0 && c >= 0 && block >= 0);
  assert(block < static_cast<int>(block_names.size()));
  triangles.emplace_back(a, b, c);
  triangle_block.push_back(block);
}

void Mesh::AddPolygon(const std::vector<Eigen::Vector3d>& points, int block) {
  assert(points.size() >= 3);
  const int base = static_cast<int>(vertices.size());
  for (const auto& p : points) vertices.push_back(p);
  for (int i = 1; i + 1 < static_cast<int>(points.size()); ++i) {
    AddTriangle(base, base + i, base + i + 1, block);
  }
}

Mesh ReadObj(const std::string& path) { return ParseObj(ReadFileToString(path), path); }

Mesh ParseObj(std::string_view text, const std::string& path) {
  text = WithoutUtf8Bom(text);
  Mesh mesh;
  std::map<std::string, int> block_index;
  std::string current = "default";
  int line_no = 0;
  size_t pos = 0;
  auto fail = [&](const std::string& problem) -> void {
    throw Error(path + ":" + std::to_string(line_no) + ": " + problem);
  };
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    std::string_view line(text.data() + pos, end - pos);
    pos = end + 1;
    ++line_no;
    const size_t hash = line.find('#');
    if (hash != std::string_view::npos) line = line.substr(0, hash);
    const auto tok = Tokens(line);
    if (tok.empty()) continue;
    const std::string_view kw = tok[0];
    if (kw == "v") {
      if (tok.size() < 4) fail("vertex needs 3 coordinates");
      Eigen::Vector3d v;
      for (int i = 0; i < 3; ++i) {
        if (!ParseDouble(tok[i + 1], &v[i])) {
          fail("bad number \"" + std::string(tok[i + 1]) + "\" in vertex");
        }
        const std::string problem = CoordinateProblem(v[i]);
        if (!problem.empty()) fail("vertex: " + problem);
      }
      mesh.vertices.push_back(v);
    } else if (kw == "f") {
      if (tok.size() < 4) {
        fail("face has " + std::to_string(tok.size() - 1) + " vertices (at least 3 needed)");
      }
      std::vector<int> idx;
      const long n = static_cast<long>(mesh.vertices.size());
      for (size_t i = 1; i < tok.size(); ++i) {
        std::string_view s = tok[i];
        const size_t slash = s.find('/');
        if (slash != std::string_view::npos) s = s.substr(0, slash);
        long k = 0;
        if (!ParseInt(s, &k)) fail("bad vertex index \"" + std::string(tok[i]) + "\"");
        const long resolved = k > 0 ? k - 1 : n + k;
        if (k == 0 || resolved < 0 || resolved >= n) {
          fail("vertex index " + std::to_string(k) + " out of range (" + std::to_string(n) +
               " vertices so far)");
        }
        idx.push_back(static_cast<int>(resolved));
      }
      auto it = block_index.find(current);
      int block;
      if (it == block_index.end()) {
        block = mesh.AddBlock(current);
        block_index[current] = block;
      } else {
        block = it->second;
      }
      if (idx.size() == 3) {
        if (IsDegenerate(mesh.vertices[idx[0]], mesh.vertices[idx[1]], mesh.vertices[idx[2]])) {
          fail("degenerate (zero-area) triangle");
        }
        mesh.AddTriangle(idx[0], idx[1], idx[2], block);
      } else {
        // Polygon: fan from the first vertex; zero-area slivers (collinear vertices) are
        // dropped, a polygon with no area at all is an error.
        int added = 0;
        for (size_t i = 1; i + 1 < idx.size(); ++i) {
          if (IsDegenerate(mesh.vertices[idx[0]], mesh.vertices[idx[i]],
                           mesh.vertices[idx[i + 1]])) {
            continue;
          }
          mesh.AddTriangle(idx[0], idx[i], idx[i + 1], block);
          ++added;
        }
        if (added == 0) fail("degenerate (zero-area) polygon");
      }
    } else if (kw == "g" || kw == "o") {
      // Names may contain spaces: take the rest of the line.
      if (tok.size() < 2) {
        current = "default";
      } else {
        const size_t start = static_cast<size_t>(tok[1].data() - line.data());
        const size_t stop =
            static_cast<size_t>(tok.back().data() + tok.back().size() - line.data());
        current = std::string(line.substr(start, stop - start));
      }
    }
    // vt, vn, usemtl, mtllib, s, l, p and unknown statements are ignored.
  }
  if (mesh.triangles.empty()) {
    throw Error(path + ": no faces (" + std::to_string(mesh.vertices.size()) +
                " vertices, no 'f' lines): the file is empty, only comments, or not a model");
  }
  return mesh;
}

std::vector<std::string> AppendObj(const std::string& path, Mesh* mesh) {
  Mesh other = ReadObj(path);
  try {
    mesh->Append(other);
  } catch (const Error& e) {
    throw Error(path + ": " + e.what());
  }
  return std::move(other.block_names);
}

void WriteObj(const std::string& path, const Mesh& mesh) {
  std::string out = "# rouen mesh: " + std::to_string(mesh.vertices.size()) + " vertices, " +
                    std::to_string(mesh.triangles.size()) + " triangles\n";
  char buf[128];
  for (const auto& v : mesh.vertices) {
    if (!v.allFinite()) throw Error(path + ": refusing to write a non-finite vertex");
    std::snprintf(buf, sizeof(buf), "v %.17g %.17g %.17g\n", v.x(), v.y(), v.z());
    out += buf;
  }
  for (int b = 0; b < static_cast<int>(mesh.block_names.size()); ++b) {
    std::string name = mesh.block_names[b];
    for (char& ch : name) {
      if (ch == '\n' || ch == '\r' || ch == '#') ch = '_';
    }
    if (name.empty()) name = "default";
    bool header = false;
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      if (mesh.triangle_block[t] != b) continue;
      if (!header) {
        out += "g " + name + "\n";
        header = true;
      }
      const auto& tri = mesh.triangles[t];
      std::snprintf(buf, sizeof(buf), "f %d %d %d\n", tri[0] + 1, tri[1] + 1, tri[2] + 1);
      out += buf;
    }
  }
  WriteFileAtomic(path, out);
}

}  // namespace rouen
