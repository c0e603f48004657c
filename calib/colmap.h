// Poses and intrinsics from a photogrammetry capture: a COLMAP sparse model (cameras, images,
// points3D; binary or text, as `colmap mapper` and `colmap model_converter` write them), and
// the similarity transform that takes its arbitrary frame to the site's east-north-up metres.
//
// COLMAP's conventions, as its format documentation gives them: an image's quaternion
// (qw, qx, qy, qz) and translation t take world points into the camera, x_cam = R x + t; the
// camera looks down +z with x right and y down (rouen's convention too), pixel centres at
// integer + 0.5. Camera models carried over exactly: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL,
// RADIAL, OPENCV (Brown-Conrady k1, k2, p1, p2), FULL_OPENCV when its rational terms k4..k6
// are zero, OPENCV_FISHEYE, SIMPLE_RADIAL_FISHEYE and RADIAL_FISHEYE (equidistant with an odd
// polynomial in the angle). Others (FOV, THIN_PRISM_FISHEYE, a FULL_OPENCV with rational
// terms) are refused by name.
#pragma once

#include <Eigen/Core>
#include <filesystem>
#include <string>
#include <vector>

#include "core/camera.h"

namespace rouen {

struct ColmapImage {
  int id = 0;
  std::string name;  // as COLMAP holds it: relative to its image folder
  int camera_id = 0;
  Intrinsics intrinsics;
  Pose pose;  // in the model's frame: x_model = rotation x_cam + position
};

struct ColmapModel {
  std::filesystem::path dir;
  bool binary = false;  // read from the .bin files (COLMAP prefers them when both exist)
  std::vector<ColmapImage> images;
  std::vector<Eigen::Vector3d> points;  // the sparse points, model frame
  // The image named `name` (exactly, else the only one with that file name), or null.
  const ColmapImage* Find(const std::string& name) const;
};

// Reads the sparse model in `dir` (cameras, images and points3D, .bin preferred to .txt).
// Throws rouen::Error naming the file (and the line of a text file) that is missing,
// truncated or malformed, or the camera model that cannot be carried over.
ColmapModel ReadColmapModel(const std::filesystem::path& dir);

// x_to = scale rotation x_from + translation.
struct Similarity {
  double scale = 1;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  Eigen::Vector3d Apply(const Eigen::Vector3d& x) const {
    return scale * (rotation * x) + translation;
  }
  // A camera pose carried along: its position moved, its axes turned (the scale leaves them).
  Pose Apply(const Pose& p) const { return {rotation * p.rotation, Apply(p.position)}; }
};

struct SimilarityFit {
  Similarity transform;
  double rms_m = 0, max_m = 0;  // residuals |T(from_i) - to_i| at the points, metres
  int points = 0;
  // "residual RMS 0.012 m, largest 0.020 m over 4 control points (scale 5)", the points
  // named by `what`.
  std::string BriefReport(const std::string& what = "control points") const;
};

// The least-squares similarity taking `from` to `to` (Umeyama 1991: centroids, the SVD of the
// cross-covariance with the reflection excluded, the scale from the variances). Throws
// rouen::Error for fewer than 3 pairs, sizes that differ, non-finite points, or points that
// do not span a plane (collinear or coincident: the rotation about their line is free).
SimilarityFit FitSimilarity(const std::vector<Eigen::Vector3d>& from,
                            const std::vector<Eigen::Vector3d>& to);

// Control points for the alignment: the same point in the model's frame and on the site.
struct ControlPoint {
  Eigen::Vector3d model = Eigen::Vector3d::Zero();
  Eigen::Vector3d enu = Eigen::Vector3d::Zero();  // east, north, up metres from the site
};
// A CSV of control points: a header naming the columns x, y, z (the model's frame) and
// east_m, north_m, up_m (the site's), in any order, then one point per line; '#' comments.
// Throws rouen::Error naming the file and the line.
std::vector<ControlPoint> ReadControlPoints(const std::filesystem::path& file);

}  // namespace rouen
