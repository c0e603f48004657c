// Trees as a survey or a map records them (OpenStreetMap's natural=tree with its height and
// diameter_crown tags, a city model's solitary vegetation, a tape and a laser rangefinder):
// a position, a height and a crown's size per tree, in the model's frame. rouen makes each a
// closed crown (an ellipsoid) on a trunk (a cylinder), geometry the surroundings take: it shades
// the building and the ground, hides their sky, and stands in front of the building in a view.
//
// The CSV's first line with data names its columns, in any order:
//   name, x_m, y_m, height_m, crown_diameter_m, crown_depth_m, trunk_diameter_m, base_z_m
// x_m, y_m (east and north of the model's origin), height_m (the crown's top above the
// tree's base) and crown_diameter_m are required; name defaults to "tree_<line>",
// crown_depth_m (the crown's vertical extent) to its diameter (a round crown), trunk_diameter_m
// to TreeMeshOptions::trunk_diameter_m, base_z_m (the ground at the trunk) to 0.
// Blank lines and lines starting with '#' are skipped.
#pragma once

#include <Eigen/Core>
#include <string>
#include <string_view>
#include <vector>

namespace rouen {

struct Tree {
  std::string name;                                    // the tree's block in the surroundings
  Eigen::Vector2d position = Eigen::Vector2d::Zero();  // east, north (m)
  double base_z_m = 0;
  double height_m = 0;          // the crown's top above base_z_m
  double crown_diameter_m = 0;  // horizontal
  double crown_depth_m = 0;     // vertical (<= height_m)
  double trunk_diameter_m = 0;  // < crown_diameter_m
};

struct TreeMeshOptions {
  // The trunk's diameter where the CSV gives none (a mature street tree's at breast height).
  double trunk_diameter_m = 0.5;
  // The crown's facets: segments around, rings from top to bottom (a 7 m crown's outline within
  // 0.12 m of the ellipse; 168 triangles, as many occluders for every point's sky); the
  // trunk's sides.
  int crown_segments = 12;
  int crown_rings = 8;
  int trunk_segments = 12;
  void Validate() const;  // throws rouen::Error
};

// The trees of a CSV file's text (`name` is the file, for messages). Throws rouen::Error naming
// the file and line for a missing required column, an unknown column, a field that is not a
// number, a size that is not positive, a crown deeper than the tree is high, a trunk as wide as
// the crown, a name that is not one word of letters, digits, '_', '-' or '.', a name used
// twice, or a file without trees.
std::vector<Tree> ParseTrees(std::string_view text, const std::string& name,
                             const TreeMeshOptions& options = {});
std::vector<Tree> ReadTrees(const std::string& path, const TreeMeshOptions& options = {});

// The trees as Wavefront OBJ text, a group per tree (its crown and trunk), faces counter-clockwise
// seen from outside, vertex indices relative (negative), so the text can follow any OBJ.
std::string TreesObjText(const std::vector<Tree>& trees, const TreeMeshOptions& options = {});

}  // namespace rouen
