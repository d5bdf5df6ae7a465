// Small analytic meshes shared by the tests.
#pragma once

#include "core/common/mesh.h"

namespace objdb::testing {

// Axis-aligned unit cube [0,1]^3: 8 vertices, 12 outward-facing triangles.
TriangleMesh unitCubeMesh();

}  // namespace objdb::testing
