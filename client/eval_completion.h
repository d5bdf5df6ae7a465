// `objdb eval`'s completion score, on the server's own answers: every
// session's scene mesh as GetSceneMesh serves it, raw and completed by the merged models. It
// reports the surface completion added and three checks of it:
//   - the session's own frames: an added point in front of a measured depth was seen through (the
//     camera saw free space there), so it is wrong;
//   - the other sessions' measured surfaces (a static scene seen twice confirms it there);
//   - with a simulator scene file in every session folder (scene.json: the synthetic lounge) the
//     true surfaces: the share of added points on them (precision) and the repeated objects' true
//     surface within 2 cm before and after completion, with its ceiling (bench/database_eval's
//     figure, here through the server).
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/common/mesh.h"
#include "core/common/status.h"

namespace objdb::cli {

struct SessionMeshes {
  std::string session;
  TriangleMesh measured, completed;
};

// Scores and prints. `folders`: session → dataset folder (its frames and scene.json).
Status printCompletionScore(const std::vector<SessionMeshes>& meshes,
                            const std::map<std::string, std::string>& folders);

}  // namespace objdb::cli
