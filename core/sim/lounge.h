// The `lounge` preset: three sessions mirroring the paper's Tango recordings (§IV) — 17 objects
// of 11 kinds in a 7 × 5 m room (cow 1, round chair 3, cube chair 1, fire extinguisher 3, gas
// cylinder 2, helmet 2, round table 1, square table 1, large box 1, small container 1, floor 1)
// plus four walls, with objects moved, turned, removed and added between sessions. Each session's
// camera makes one lap looking outward (objects by the walls seen from the front only, their backs
// never) and one lap looking inward (central objects seen from all sides).
#pragma once

#include <string>
#include <vector>

#include "core/sim/scene.h"

namespace objdb::sim {

struct LoungeOptions {
  std::string camera = "tango";  // intrinsics preset
  int frames_per_session = 300;
  uint64_t seed = 1;             // noise seed; session k uses seed + k
  bool noise = true;
};

// Returns the three session scenes, named "session_1" .. "session_3".
StatusOr<std::vector<Scene>> loungePreset(const LoungeOptions& options = {});

// A small two-box scene (two boxes on a floor, a short arc of views): unit tests and demos.
Scene twoBoxesScene(const std::string& camera = "vga", int frames = 30);

// Names of the presets objdb sim knows.
const std::vector<std::string>& presetNames();

}  // namespace objdb::sim
