// Camera pose from 2D-3D landmark correspondences to the building model (Yu & Malik 1998
// sec. 6: camera positions and orientations calibrated against the FACADE model; sec. 3.2:
// buildings as landmarks in sky photographs): PnP with RANSAC on normalised rays, then Ceres
// refinement of the pixel reprojection error through core/camera.h's Project.
//
// Landmark file (JSON; paths relative to the file):
//   {
//     "image": "photos/west.jpg",            // optional, informational
//     "model": "building.obj",               // optional; needed for "vertex" references
//     "points": [
//       {"name": "NW roof corner", "pixel": [812.5, 140.0], "world": [12.0, 30.5, 18.2]},
//       {"name": "door left", "pixel": [640.0, 902.0], "vertex": 17}
//     ]
//   }
// "pixel" is in rouen's convention (pixel centres at integer + 0.5, x right, y down) of the
// image the lens file describes; "world" is the site frame (ENU metres); "vertex" is a
// 0-based index into the model's OBJ vertices. Each point has exactly one of world/vertex.
#pragma once

#include <Eigen/Core>
#include <nlohmann/json_fwd.hpp>
#include <string>
#include <vector>

#include "core/camera.h"

namespace rouen {

struct Landmark {
  std::string name;
  Eigen::Vector2d pixel;  // rouen pixel convention
  Eigen::Vector3d world;  // ENU metres
};

struct LandmarkFile {
  std::string image;  // as written in the file (may be empty)
  std::vector<Landmark> points;
};

// Reads and checks a landmark file; vertex references are resolved through the OBJ model.
// Throws rouen::Error naming the file and the point for malformed input.
LandmarkFile ReadLandmarks(const std::string& path);

struct PoseOptions {
  double inlier_threshold_px = 4.0;  // RANSAC and final inlier test, pixels
  double ransac_confidence = 0.999;
  int ransac_iterations = 2000;
  double huber_px = 2.0;  // robust loss scale in the refinement, pixels
  int min_inliers = 4;
  void Validate() const;  // throws rouen::Error
};

struct PointReport {
  std::string name;
  double error_px = 0;  // reprojection distance, pixels; -1 when the point does not project
  bool inlier = false;
  bool behind = false;  // behind the camera (or outside a fisheye's field of view)
};

struct PoseSummary {
  Pose pose;
  double rms_px = 0;  // over inliers
  double max_px = 0;  // over inliers
  int inliers = 0;
  std::vector<PointReport> points;  // in input order
  int ransac_used = 0;              // points inside the normalisable field (< 85 deg off-axis)
  int ceres_iterations = 0;
  double seconds = 0;
};

// Estimates the camera pose. Throws rouen::Error (never returns NaN) when there are fewer than
// 4 landmarks, the world points are (nearly) collinear or coincide, pixels are non-finite or
// far outside the image, RANSAC finds no consistent pose, fewer than min_inliers inliers
// remain, or the inliers lie behind the camera.
PoseSummary EstimatePose(const Intrinsics& camera, const std::vector<Landmark>& points,
                         const PoseOptions& options = {});

// The pose as core/camera.h writes it ({"rotation", "position"}) plus a "reprojection"
// object {rms_px, max_px, inliers, points: [{name, error_px, inlier}]}, which Pose readers
// ignore.
nlohmann::json PoseJson(const PoseSummary& summary);

}  // namespace rouen
