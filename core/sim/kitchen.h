// The `kitchen` preset: two sessions in a 5 × 4 m kitchen for testing object grouping in
// real-room conditions — an L-shaped run of fitted cabinets with counter tops flush against two
// walls, wall cabinets, a shelf and a fridge-sized tall cabinet (room structure), a dining table
// with four identical chairs tucked in until their seats nearly touch the table top's edge, mugs,
// a bowl and a bottle on the counter, a rug, baseboards and long walls bent by 1.5°. Depth noise
// quantises disparity like a structured-light sensor and the written poses drift by ~2 cm.
#pragma once

#include <string>
#include <vector>

#include "core/sim/scene.h"

namespace objdb::sim {

struct KitchenOptions {
  std::string camera = "vga";    // intrinsics preset
  int frames_per_session = 240;  // 40..100000
  uint64_t seed = 1;             // noise and drift seed; session k uses seed + k
  bool noise = true;             // depth noise, disparity quantisation included
  bool drift = true;             // written poses drift from the rendered ones (Scene::drift)
};

// Returns the two session scenes, "session_1" and "session_2", in one world frame (z up, floor at
// z = 0, room corner at the origin). Ids: 1 dining table, 2–5 dining chairs, 6–7 mugs, 8 bowl,
// 9 bottle (objects); 20 floor, 21 rug, 30–36 base cabinets, 40–41 counter tops, 42 tall
// cabinet, 43–45 wall cabinets, 46 shelf, 101–106 wall pieces, 111–116 baseboards (structure).
StatusOr<std::vector<Scene>> kitchenPreset(const KitchenOptions& options = {});

}  // namespace objdb::sim
