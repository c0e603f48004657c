// The ground around the building as part of the model (beyond Yu & Malik 1998, whose §3.3
// environment holds the ground only as directions seen from the panoramas). A panorama taken on
// one side of a building cannot see the ground on the other side, which a low sun lights and the
// building's long shadow darkens, yet that ground is the main light of a shaded wall facing it.
// Made a surface of the model, the ground near the building gets grid points like any face: its
// albedo from the architecture photos (§4), its irradiance from the sun with the building's cast
// shadow and from the sky, and its light reaches the walls through the interreflection (§4.1);
// only the ground beyond it is still read from the panoramas.
#pragma once

#include <nlohmann/json_fwd.hpp>
#include <string>

#include "core/mesh.h"
#include "solve/raycast.h"

namespace rouen {

struct GroundApronOptions {
  // How far beyond the model's footprint (its bounding box in plan) the ground is modelled,
  // metres; 0: not at all.
  double radius_m = 0;
  // Resolution of the outline around the building's base: cells of this size are kept or left
  // out (under the building, or where the model already has ground) by their centre, metres.
  double cell_m = 0.5;
  // Longest side of one ground face, metres: the cells are merged into rectangles no longer,
  // so that the grid on them stays even (each face is gridded on its own).
  double max_face_m = 8;
  std::string block = "ground";  // the block the ground faces go in
  // The grid spacing on it (the pipeline's grid.block_spacing_m for `block` unless set there):
  // seen at grazing angles and lit smoothly but for the building's shadow, it needs fewer
  // points than the building, metres.
  double spacing_m = 1.5;

  void Validate() const;  // throws rouen::Error naming the bad field
};

struct GroundApronSummary {
  int faces = 0;              // rectangles added (two triangles each)
  int cells_kept = 0;         // outline cells that became ground
  int cells_under_model = 0;  // outline cells left out: under the model or its own ground
  double area_m2 = 0;
  double level_z = 0;  // the ground's height (GroundLevel: the model's lowest vertex)
};

// Adds the ground around `mesh`, as seen through `model` (its ray caster), to `mesh` in block
// options.block: the level rectangle of the model's bounding box in plan grown by radius_m, at
// the model's lowest vertex, facing up, less the cells whose centre lies under the model (a ray
// up from just below the ground meets the back of a face first: inside the building, or under
// a level face the model already has, e.g. a plaza). Nothing is added for radius_m = 0.
// Throws rouen::Error when the block already exists in the model or the options are bad.
GroundApronSummary AddGroundApron(const RayCaster& model, const GroundApronOptions& options,
                                  Mesh* mesh);
// `model` with its ground added (AddGroundApron through a ray caster of `model`); `model` as it
// is for radius_m = 0. `summary` may be null.
Mesh WithGroundApron(Mesh model, const GroundApronOptions& options,
                     GroundApronSummary* summary = nullptr);

void to_json(nlohmann::json& j, const GroundApronOptions& o);
// Validates; a missing key keeps its default.
void from_json(const nlohmann::json& j, GroundApronOptions& o);

}  // namespace rouen
