// "What is here?": where the stored objects stand in a session's world, and what changed between
// two sessions. A placement is one observation of a model: its pose in the session's world and
// the model's box in its own frame. Pure functions over placements the store lists
// (storage::Store::modelSummaries filtered by session: the observations index finds a session's
// rows), so both backends answer alike.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "core/common/status.h"
#include "core/common/transform.h"

namespace objdb::database {

struct Placement {
  int64_t model_id = 0;
  Transform T_world_object = Transform::Identity();
  Eigen::AlignedBox3d bounds_object;  // the model's box in its frame
  // The model's centre (its box's middle) in the world: where the placement is (what
  // model::samePlace compares).
  Eigen::Vector3d centre() const { return T_world_object * bounds_object.center(); }
  // The model's box turned into the world: the axis-aligned box holding it.
  Eigen::AlignedBox3d worldBox() const;
};

// A box (min ≤ max on every axis) or a ball, in a session's world frame. A placement is in it
// when its centre is.
struct Region {
  std::optional<Eigen::AlignedBox3d> box;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  double radius_m = 0.0;  // the ball's, when there is no box
};
// INVALID_ARGUMENT naming the field ("box.min.x 2 > box.max.x 1", "radius_m", a value not
// finite). Field names as the API's: box.min, box.max, centre, radius_m.
Status validateRegion(const Region& region);
bool inRegion(const Placement& placement, const Region& region);

// One model's placements in two sessions (both in one world frame, as sessions of one map are).
struct PlacementChange {
  int64_t model_id = 0;
  std::vector<Placement> before, after;  // in the first session, in the second
  // Moved: the largest distance from a place in one session to the nearest place of the same
  // model in the other, metres (0 when it was not in both).
  double moved_m = 0.0;
};
struct SessionChanges {
  std::vector<PlacementChange> added;    // in the second session only
  std::vector<PlacementChange> removed;  // in the first only
  std::vector<PlacementChange> moved;    // in both, not at the same places
  size_t unchanged = 0;                  // in both at the same places
};
// Placements within `same_place_m` of each other (model::kSamePlaceM: one surface, one place)
// are the same place. Each list by model id.
SessionChanges changesBetween(const std::vector<Placement>& first,
                              const std::vector<Placement>& second, double same_place_m);

}  // namespace objdb::database
