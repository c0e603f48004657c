#include "calib/colmap.h"

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iomanip>
#include <map>
#include <sstream>

#include "core/error.h"
#include "core/files.h"
#include "core/text.h"

namespace rouen {
namespace {

namespace fs = std::filesystem;

struct CameraModel {
  const char* name;
  int id;      // COLMAP's model_id in the binary files
  int params;  // how many
};

// COLMAP's camera models (its documentation's table), in model_id order.
constexpr CameraModel kModels[] = {{"SIMPLE_PINHOLE", 0, 3},
                                   {"PINHOLE", 1, 4},
                                   {"SIMPLE_RADIAL", 2, 4},
                                   {"RADIAL", 3, 5},
                                   {"OPENCV", 4, 8},
                                   {"OPENCV_FISHEYE", 5, 8},
                                   {"FULL_OPENCV", 6, 12},
                                   {"FOV", 7, 5},
                                   {"SIMPLE_RADIAL_FISHEYE", 8, 4},
                                   {"RADIAL_FISHEYE", 9, 5},
                                   {"THIN_PRISM_FISHEYE", 10, 12}};

const CameraModel* ModelByName(const std::string& name) {
  for (const CameraModel& m : kModels)
    if (name == m.name) return &m;
  return nullptr;
}

const CameraModel* ModelById(int id) {
  for (const CameraModel& m : kModels)
    if (id == m.id) return &m;
  return nullptr;
}

// rouen's intrinsics for a COLMAP camera; throws rouen::Error (no file named: the caller adds
// it) for a model rouen's projections cannot hold.
Intrinsics ToIntrinsics(const CameraModel& m, int64_t width, int64_t height,
                        const std::vector<double>& p) {
  for (double v : p)
    if (!std::isfinite(v)) throw Error("a parameter of the camera is not finite");
  if (width <= 0 || height <= 0 || width > (1 << 20) || height > (1 << 20))
    throw Error("image size " + std::to_string(width) + "x" + std::to_string(height) +
                " is not a camera's");
  Intrinsics k;
  k.width = static_cast<int>(width);
  k.height = static_cast<int>(height);
  const std::string name = m.name;
  const bool single_f = name == "SIMPLE_PINHOLE" || name == "SIMPLE_RADIAL" || name == "RADIAL" ||
                        name == "SIMPLE_RADIAL_FISHEYE" || name == "RADIAL_FISHEYE";
  if (single_f) {
    k.fx = k.fy = p[0];
    k.cx = p[1];
    k.cy = p[2];
  } else {
    k.fx = p[0];
    k.fy = p[1];
    k.cx = p[2];
    k.cy = p[3];
  }
  if (name == "SIMPLE_RADIAL" || name == "SIMPLE_RADIAL_FISHEYE") {
    k.k1 = p[3];
  } else if (name == "RADIAL" || name == "RADIAL_FISHEYE") {
    k.k1 = p[3];
    k.k2 = p[4];
  } else if (name == "OPENCV" || name == "FULL_OPENCV") {
    k.k1 = p[4];
    k.k2 = p[5];
    k.p1 = p[6];
    k.p2 = p[7];
    if (name == "FULL_OPENCV") {
      k.k3 = p[8];
      if (p[9] != 0 || p[10] != 0 || p[11] != 0)
        throw Error(
            "camera model FULL_OPENCV with rational distortion (k4, k5, k6 not zero) cannot be "
            "carried over; refine the model with OPENCV or OPENCV_FISHEYE");
    }
  } else if (name == "OPENCV_FISHEYE") {
    k.k1 = p[4];
    k.k2 = p[5];
    k.k3 = p[6];
    k.k4 = p[7];
  } else if (name == "FOV" || name == "THIN_PRISM_FISHEYE") {
    throw Error("camera model " + name +
                " cannot be carried over (rouen's cameras: pinhole with Brown-Conrady "
                "distortion, equidistant fisheye); use OPENCV or OPENCV_FISHEYE");
  }
  if (name.find("FISHEYE") != std::string::npos) k.projection = Projection::kFisheye;
  k.Validate();
  return k;
}

// COLMAP's image pose (world to camera: quaternion and translation) as rouen's camera pose.
Pose ToPose(const double q[4], const double t[3]) {
  const Eigen::Quaterniond quat(q[0], q[1], q[2], q[3]);
  const double n = quat.norm();
  if (!std::isfinite(n) || n < 1e-9 || !std::isfinite(t[0] + t[1] + t[2]))
    throw Error("the image's pose is not a finite rotation and translation");
  const Eigen::Matrix3d r = quat.normalized().toRotationMatrix();
  Pose pose;
  pose.rotation = r.transpose();
  pose.position = -(r.transpose() * Eigen::Vector3d(t[0], t[1], t[2]));
  return pose;
}

// ---- text files -------------------------------------------------------------------------

// The data lines of a COLMAP text file, with their numbers (comments skipped; empty lines kept:
// an image's point line may be empty).
std::vector<std::pair<int, std::string>> TextLinesOf(const fs::path& file) {
  std::istringstream in(ReadFileToString(file));
  std::vector<std::pair<int, std::string>> lines;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!line.empty() && line[0] == '#') continue;
    lines.emplace_back(number, line);
  }
  return lines;
}

std::vector<std::string> Fields(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> out;
  for (std::string f; in >> f;) out.push_back(f);
  return out;
}

double ToDouble(const std::string& s) {
  size_t used = 0;
  double v = 0;
  try {
    v = std::stod(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size() || !std::isfinite(v)) throw Error("'" + s + "' is not a finite number");
  return v;
}

int64_t ToInt(const std::string& s) {
  size_t used = 0;
  long long v = 0;
  try {
    v = std::stoll(s, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  if (used != s.size()) throw Error("'" + s + "' is not a whole number");
  return v;
}

struct RawCamera {
  const CameraModel* model = nullptr;
  int64_t width = 0, height = 0;
  std::vector<double> params;
};

std::map<int, Intrinsics> ReadCamerasText(const fs::path& file) {
  std::map<int, Intrinsics> cameras;
  for (const auto& [number, line] : TextLinesOf(file)) {
    const std::vector<std::string> f = Fields(line);
    if (f.empty()) continue;
    const std::string where = file.string() + ":" + std::to_string(number) + ": ";
    try {
      if (f.size() < 4) throw Error("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
      const CameraModel* m = ModelByName(f[1]);
      if (!m) throw Error("unknown camera model '" + f[1] + "'");
      if (static_cast<int>(f.size()) != 4 + m->params)
        throw Error(std::string(m->name) + " has " + std::to_string(m->params) +
                    " parameters, the line " + std::to_string(f.size() - 4));
      std::vector<double> p;
      for (size_t i = 4; i < f.size(); ++i) p.push_back(ToDouble(f[i]));
      const int id = static_cast<int>(ToInt(f[0]));
      if (!cameras.emplace(id, ToIntrinsics(*m, ToInt(f[2]), ToInt(f[3]), p)).second)
        throw Error("camera " + f[0] + " given twice");
    } catch (const Error& e) {
      throw Error(where + e.what());
    }
  }
  return cameras;
}

std::vector<ColmapImage> ReadImagesText(const fs::path& file,
                                        const std::map<int, Intrinsics>& cameras) {
  std::vector<ColmapImage> images;
  const auto lines = TextLinesOf(file);
  for (size_t i = 0; i < lines.size(); ++i) {
    const auto& [number, line] = lines[i];
    const std::vector<std::string> f = Fields(line);
    if (f.empty()) continue;
    const std::string where = file.string() + ":" + std::to_string(number) + ": ";
    try {
      if (f.size() < 10) throw Error("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
      ColmapImage im;
      im.id = static_cast<int>(ToInt(f[0]));
      const double q[4] = {ToDouble(f[1]), ToDouble(f[2]), ToDouble(f[3]), ToDouble(f[4])};
      const double t[3] = {ToDouble(f[5]), ToDouble(f[6]), ToDouble(f[7])};
      im.pose = ToPose(q, t);
      im.camera_id = static_cast<int>(ToInt(f[8]));
      // The name is the rest of the line (it may hold spaces).
      size_t at = 0;
      for (int k = 0; k < 9; ++k) {
        at = line.find_first_not_of(" \t", at);
        at = line.find_first_of(" \t", at);
      }
      im.name = Trimmed(line.substr(at));
      const auto cam = cameras.find(im.camera_id);
      if (cam == cameras.end()) throw Error("camera " + f[8] + " is not in cameras.txt");
      im.intrinsics = cam->second;
      images.push_back(std::move(im));
    } catch (const Error& e) {
      throw Error(where + e.what());
    }
    ++i;  // the image's line of 2D points (possibly empty) follows
  }
  return images;
}

std::vector<Eigen::Vector3d> ReadPointsText(const fs::path& file) {
  std::vector<Eigen::Vector3d> points;
  for (const auto& [number, line] : TextLinesOf(file)) {
    const std::vector<std::string> f = Fields(line);
    if (f.empty()) continue;
    try {
      if (f.size() < 8) throw Error("expected POINT3D_ID X Y Z R G B ERROR TRACK[]");
      points.emplace_back(ToDouble(f[1]), ToDouble(f[2]), ToDouble(f[3]));
    } catch (const Error& e) {
      throw Error(file.string() + ":" + std::to_string(number) + ": " + e.what());
    }
  }
  return points;
}

// ---- binary files -----------------------------------------------------------------------

// Little-endian fields from a file held whole, every read bounds-checked.
class BinaryReader {
 public:
  explicit BinaryReader(const fs::path& file) : file_(file), data_(ReadFileToString(file)) {}
  template <typename T>
  T Read() {
    static_assert(std::is_trivially_copyable_v<T>);
    if (data_.size() - at_ < sizeof(T)) Truncated();
    T v;
    std::memcpy(&v, data_.data() + at_, sizeof(T));  // little-endian hosts (x86, ARM) only
    at_ += sizeof(T);
    return v;
  }
  std::string ReadCString() {
    const size_t end = data_.find('\0', at_);
    if (end == std::string::npos) Truncated();
    std::string s = data_.substr(at_, end - at_);
    at_ = end + 1;
    return s;
  }
  void Skip(uint64_t bytes) {
    if (data_.size() - at_ < bytes) Truncated();
    at_ += bytes;
  }
  // A count of records of at least `min_bytes` each, checked against what the file holds.
  uint64_t ReadCount(uint64_t min_bytes) {
    const uint64_t n = Read<uint64_t>();
    if (min_bytes > 0 && n > (data_.size() - at_) / min_bytes) Truncated();
    return n;
  }
  [[noreturn]] void Fail(const std::string& what) const {
    throw Error(file_.string() + ": at byte " + std::to_string(at_) + ": " + what);
  }

 private:
  [[noreturn]] void Truncated() const { Fail("the file ends early (truncated?)"); }
  fs::path file_;
  std::string data_;
  size_t at_ = 0;
};

std::map<int, Intrinsics> ReadCamerasBinary(const fs::path& file) {
  BinaryReader r(file);
  std::map<int, Intrinsics> cameras;
  const uint64_t n = r.ReadCount(4 + 4 + 8 + 8);
  for (uint64_t i = 0; i < n; ++i) {
    const uint32_t id = r.Read<uint32_t>();
    const int32_t model_id = r.Read<int32_t>();
    const uint64_t width = r.Read<uint64_t>(), height = r.Read<uint64_t>();
    const CameraModel* m = ModelById(model_id);
    if (!m) r.Fail("unknown camera model id " + std::to_string(model_id));
    std::vector<double> p(m->params);
    for (double& v : p) v = r.Read<double>();
    try {
      if (!cameras
               .emplace(static_cast<int>(id),
                        ToIntrinsics(*m, static_cast<int64_t>(std::min<uint64_t>(width, 1 << 30)),
                                     static_cast<int64_t>(std::min<uint64_t>(height, 1 << 30)), p))
               .second)
        throw Error("given twice");
    } catch (const Error& e) {
      r.Fail("camera " + std::to_string(id) + ": " + e.what());
    }
  }
  return cameras;
}

std::vector<ColmapImage> ReadImagesBinary(const fs::path& file,
                                          const std::map<int, Intrinsics>& cameras) {
  BinaryReader r(file);
  std::vector<ColmapImage> images;
  const uint64_t n = r.ReadCount(4 + 7 * 8 + 4 + 1 + 8);
  for (uint64_t i = 0; i < n; ++i) {
    ColmapImage im;
    im.id = static_cast<int>(r.Read<uint32_t>());
    double q[4], t[3];
    for (double& v : q) v = r.Read<double>();
    for (double& v : t) v = r.Read<double>();
    im.camera_id = static_cast<int>(r.Read<uint32_t>());
    im.name = r.ReadCString();
    const uint64_t points2d = r.ReadCount(8 + 8 + 8);
    r.Skip(points2d * (8 + 8 + 8));
    try {
      im.pose = ToPose(q, t);
      const auto cam = cameras.find(im.camera_id);
      if (cam == cameras.end())
        throw Error("camera " + std::to_string(im.camera_id) + " is not in cameras.bin");
      im.intrinsics = cam->second;
    } catch (const Error& e) {
      r.Fail("image " + std::to_string(im.id) + " (" + im.name + "): " + e.what());
    }
    images.push_back(std::move(im));
  }
  return images;
}

std::vector<Eigen::Vector3d> ReadPointsBinary(const fs::path& file) {
  BinaryReader r(file);
  std::vector<Eigen::Vector3d> points;
  const uint64_t n = r.ReadCount(8 + 3 * 8 + 3 + 8 + 8);
  points.reserve(n);
  for (uint64_t i = 0; i < n; ++i) {
    r.Read<uint64_t>();  // POINT3D_ID
    Eigen::Vector3d x;
    for (int c = 0; c < 3; ++c) x[c] = r.Read<double>();
    if (!x.allFinite()) r.Fail("point " + std::to_string(i) + " is not finite");
    r.Skip(3 + 8);  // colour, error
    const uint64_t track = r.ReadCount(4 + 4);
    r.Skip(track * (4 + 4));
    points.push_back(x);
  }
  return points;
}

}  // namespace

const ColmapImage* ColmapModel::Find(const std::string& name) const {
  for (const ColmapImage& im : images)
    if (im.name == name) return &im;
  const ColmapImage* found = nullptr;
  const std::string file = fs::path(name).filename().string();
  for (const ColmapImage& im : images) {
    if (fs::path(im.name).filename().string() != file) continue;
    if (found) return nullptr;  // two images of that file name: neither is meant
    found = &im;
  }
  return found;
}

ColmapModel ReadColmapModel(const fs::path& dir) {
  ColmapModel model;
  model.dir = dir;
  std::error_code ec;
  if (!fs::is_directory(dir, ec))
    throw Error(dir.string() + ": no such folder (a COLMAP sparse model, e.g. sparse/0)");
  const bool bin = fs::exists(dir / "cameras.bin", ec) && fs::exists(dir / "images.bin", ec);
  const bool txt = fs::exists(dir / "cameras.txt", ec) && fs::exists(dir / "images.txt", ec);
  if (!bin && !txt)
    throw Error(dir.string() +
                ": no COLMAP sparse model (cameras and images, .bin or .txt) in this folder");
  model.binary = bin;
  const char* ext = bin ? ".bin" : ".txt";
  const fs::path cameras_file = dir / (std::string("cameras") + ext);
  const fs::path images_file = dir / (std::string("images") + ext);
  const fs::path points_file = dir / (std::string("points3D") + ext);
  const std::map<int, Intrinsics> cameras =
      bin ? ReadCamerasBinary(cameras_file) : ReadCamerasText(cameras_file);
  model.images =
      bin ? ReadImagesBinary(images_file, cameras) : ReadImagesText(images_file, cameras);
  if (fs::exists(points_file, ec))
    model.points = bin ? ReadPointsBinary(points_file) : ReadPointsText(points_file);
  if (model.images.empty()) throw Error(images_file.string() + ": no registered image");
  return model;
}

std::string SimilarityFit::BriefReport(const std::string& what) const {
  std::ostringstream os;
  os << std::fixed << std::setprecision(3) << "residual RMS " << rms_m << " m, largest " << max_m
     << " m over " << points << " " << what << " (scale " << std::defaultfloat
     << std::setprecision(6) << transform.scale << ")";
  return os.str();
}

SimilarityFit FitSimilarity(const std::vector<Eigen::Vector3d>& from,
                            const std::vector<Eigen::Vector3d>& to) {
  if (from.size() != to.size())
    throw Error("similarity: " + std::to_string(from.size()) + " points to map onto " +
                std::to_string(to.size()));
  const int n = static_cast<int>(from.size());
  if (n < 3)
    throw Error("similarity: " + std::to_string(n) + " point pairs; at least 3 not on a line");
  Eigen::Vector3d mx = Eigen::Vector3d::Zero(), my = Eigen::Vector3d::Zero();
  for (int i = 0; i < n; ++i) {
    if (!from[i].allFinite() || !to[i].allFinite())
      throw Error("similarity: point pair " + std::to_string(i + 1) + " is not finite");
    mx += from[i];
    my += to[i];
  }
  mx /= n;
  my /= n;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero(), sxx = Eigen::Matrix3d::Zero(),
                  syy = Eigen::Matrix3d::Zero();
  double var_x = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d x = from[i] - mx, y = to[i] - my;
    cov += y * x.transpose();
    sxx += x * x.transpose();
    syy += y * y.transpose();
    var_x += x.squaredNorm();
  }
  // Both sets must span a plane: the second singular value of their spread not negligible.
  for (const Eigen::Matrix3d* s : {&sxx, &syy}) {
    const Eigen::Vector3d sv = Eigen::JacobiSVD<Eigen::Matrix3d>(*s).singularValues();
    if (!(sv[0] > 0) || sv[1] < 1e-10 * sv[0])
      throw Error(
          "similarity: the points lie on a line (or coincide); give 3 or more not on "
          "one line");
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cov / n, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d s = Eigen::Matrix3d::Identity();
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0) s(2, 2) = -1;
  SimilarityFit fit;
  fit.transform.rotation = svd.matrixU() * s * svd.matrixV().transpose();
  fit.transform.scale = (svd.singularValues().asDiagonal() * s).trace() / (var_x / n);
  fit.transform.translation = my - fit.transform.scale * (fit.transform.rotation * mx);
  double sum = 0;
  for (int i = 0; i < n; ++i) {
    const double r = (fit.transform.Apply(from[i]) - to[i]).norm();
    sum += r * r;
    fit.max_m = std::max(fit.max_m, r);
  }
  fit.rms_m = std::sqrt(sum / n);
  fit.points = n;
  return fit;
}

std::vector<ControlPoint> ReadControlPoints(const fs::path& file) {
  const std::vector<std::string> lines = ReadTextLines(file.string(), "a control point CSV");
  static const char* kColumns[] = {"x", "y", "z", "east_m", "north_m", "up_m"};
  std::vector<int> column(6, -1);
  std::vector<ControlPoint> points;
  bool header = false;
  for (size_t i = 0; i < lines.size(); ++i) {
    const std::string line = Trimmed(lines[i]);
    if (line.empty() || line[0] == '#') continue;
    const std::string where = file.string() + ":" + std::to_string(i + 1) + ": ";
    const std::vector<std::string> f = CsvFields(line);
    if (!header) {
      for (size_t c = 0; c < f.size(); ++c)
        for (int k = 0; k < 6; ++k)
          if (f[c] == kColumns[k]) column[k] = static_cast<int>(c);
      for (int k = 0; k < 6; ++k)
        if (column[k] < 0)
          throw Error(where + "the header names no column '" + kColumns[k] +
                      "' (expected x,y,z,east_m,north_m,up_m)");
      header = true;
      continue;
    }
    ControlPoint p;
    try {
      for (int k = 0; k < 6; ++k) {
        if (column[k] >= static_cast<int>(f.size()))
          throw Error("no value for '" + std::string(kColumns[k]) + "'");
        (k < 3 ? p.model : p.enu)[k % 3] = ToDouble(f[column[k]]);
      }
    } catch (const Error& e) {
      throw Error(where + e.what());
    }
    points.push_back(p);
  }
  if (!header) throw Error(file.string() + ": no header and no control point");
  return points;
}

}  // namespace rouen
