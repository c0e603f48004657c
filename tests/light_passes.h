// rouen's irradiance against Cycles' light passes, for the Blender worlds of tests/data whose
// views carry Diffuse Direct and Indirect passes (passes/t<slot>_<group>_diff{dir,ind}.exr:
// the diffuse light without the albedo, the true irradiance of every pixel's surface) and a
// truth.json with each block's roughness and each time's slot.
#ifndef ROUEN_TESTS_LIGHT_PASSES_H_
#define ROUEN_TESTS_LIGHT_PASSES_H_

#include <Eigen/Core>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace rouen::light_passes {

// The ground beside the walls (the observed cells of the scene's ground field that see less than
// half the sky) as the field predicts it at `slot` under that slot's measured lighting, against
// the world's landscape panoramas then (t<slot>_<group>.exr, every pixel on such ground): per
// channel, rouen's radiance over Cycles' summed over the pixels, of the ground then in shadow
// and in sun; printed. Fails the calling test (gtest) on a scene without a field.
struct GroundPrediction {
  Eigen::Vector3d shaded_ratio = Eigen::Vector3d::Zero(), sunlit_ratio = Eigen::Vector3d::Zero();
  int shaded = 0, sunlit = 0;  // pixels
};
GroundPrediction GroundBesideWalls(const std::filesystem::path& data,
                                   const std::filesystem::path& scene_dir, int slot);

// `rouen import` of the world in `data` as a user runs it (its photos, list, cameras, the site
// from truth.json, building.obj, the sky segmented): append " --surroundings ..." and " --out ...".
std::string ImportCommand(const std::filesystem::path& data);

// The user's path on the world in `data`, held out at its truth.json's held-out slot: `rouen
// import` (ImportCommand and `import_options`) into dir/<name>_session, `rouen solve
// --holdout-slot` (and `solve_options`) into dir/<name>_scene, `rouen validate --json` of that
// slot. `log` holds every command's output; `validation` validate's JSON, empty when a command
// failed (the caller asserts on it, with the log).
struct HeldOutRun {
  std::filesystem::path session, scene;
  std::string log;
  nlohmann::json validation;
};
HeldOutRun RunHeldOut(const std::filesystem::path& data, const std::filesystem::path& dir,
                      const std::string& name, const std::string& import_options,
                      const std::string& solve_options = "");

// Sums over a set of visible grid points: Cycles' passes x pi and rouen's terms in the same
// units (the block's Burley factor for the sun, its ambient factor for the rest).
struct TermSums {
  int points = 0;
  Eigen::Vector3d truth_direct = Eigen::Vector3d::Zero(), truth_indirect = Eigen::Vector3d::Zero();
  Eigen::Vector3d sun = Eigen::Vector3d::Zero(), sky = Eigen::Vector3d::Zero(),
                  env = Eigen::Vector3d::Zero(), bounce = Eigen::Vector3d::Zero();
  void Add(const TermSums& o);
  // rouen / Cycles per channel: all the light (sun, sky, environment, interreflection
  // against Diffuse Direct + Indirect), and the sun and sky against the direct light alone.
  // rouen's sky is what arrives from above the horizon, the landscape photographed there
  // included, which Cycles counts as indirect: only the total compares like with like.
  Eigen::Vector3d TotalRatio() const;
  Eigen::Vector3d DirectRatio() const;
  Eigen::Vector3d Share(const Eigen::Vector3d& term) const;
};

// rouen's irradiance at the grid points the views see whole, term by term, against Cycles'
// Diffuse Direct and Indirect passes of the world in `data`, under each slot's measured
// lighting of the scene in `scene_dir` (`predicted`: the lighting predicted for the slot's
// time from the other slots, §5): keyed "<slot> <block> sunlit|shaded" and
// "all <block> sunlit|shaded" (pooled over the slots), each printed. Only the blocks of
// truth.json's "blocks" (the building) are summed, never the surroundings. Fails the calling
// test (gtest) on a missing pass or camera.
std::map<std::string, TermSums> TermTable(const std::filesystem::path& data,
                                          const std::filesystem::path& scene_dir,
                                          bool predicted = false);

// Per block of truth.json's "blocks" (never the surroundings) and channel: the base colour and
// the median pseudo-albedos (sun; sky and environment) over the block's observed grid points of
// the scene in `scene_dir`, each printed. With `both_lit_and_shaded`, only the points the photos
// saw both in sun and in shadow (eqs. 11 and 12 both present: neither flagged never-shadowed nor
// sun-unobserved), where the photos alone determine both albedos. Fails the calling test (gtest)
// on a block with 100 such points or fewer.
struct BlockAlbedo {
  std::string block;
  int channel = 0;
  bool glossy = false;
  double base = 0, rho_sun = 0, rho_se = 0;
  int points = 0;  // the observed grid points the medians are over
};
std::vector<BlockAlbedo> BlockAlbedos(const std::filesystem::path& data,
                                      const std::filesystem::path& scene_dir,
                                      bool both_lit_and_shaded = false);
// The same for the surroundings (truth.json's "surroundings" that surroundings.obj holds), each
// printed; a block no photo observed has points 0 and albedos 0.
std::vector<BlockAlbedo> SurroundingAlbedos(const std::filesystem::path& data,
                                            const std::filesystem::path& scene_dir);

}  // namespace rouen::light_passes

#endif  // ROUEN_TESTS_LIGHT_PASSES_H_
