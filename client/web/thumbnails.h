// Thumbnails of object models for `objdb web`'s gallery, rendered here with objdb's own
// rasteriser (core/sim/renderer.h): the mesh shaded by a headlight in its mean vertex colour,
// from two directions (view 0 from the front left and above, view 1 from the back right), on
// white, as PNG.
#pragma once

#include <string>

#include "core/common/mesh.h"
#include "core/common/status.h"

namespace objdb::web {

inline constexpr int kThumbnailViews = 2;

// PNG bytes of `mesh` (in its own frame, +z up) seen from view 0 or 1, width × height pixels.
// Errors: an empty mesh (FAILED_PRECONDITION), a view or size out of range (INVALID_ARGUMENT).
StatusOr<std::string> renderThumbnail(const TriangleMesh& mesh, int view, int width = 192,
                                      int height = 144);

}  // namespace objdb::web
