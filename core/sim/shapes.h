// Procedural triangle-mesh primitives for the synthetic world (boxes, cylinders, cones, spheres,
// tori, planes). All are closed and outward-oriented unless said otherwise; sizes in metres.
#pragma once

#include "core/common/mesh.h"

namespace objdb::sim {

// Axis-aligned box centred at the origin with edge lengths `size`.
TriangleMesh makeBox(const Eigen::Vector3f& size);
// Cylinder along z from z = 0 to z = height, closed with caps.
TriangleMesh makeCylinder(float radius, float height, int segments = 32);
// Cone along z from a base disc at z = 0 to the apex at z = height, closed.
TriangleMesh makeCone(float radius, float height, int segments = 32);
// Sphere centred at the origin, from the north pole (+z) down to the polar angle
// `max_polar_rad` (π = full closed sphere, π/2 = upper hemisphere, open at the cut).
TriangleMesh makeSphere(float radius, int rings = 16, int segments = 32,
                        float max_polar_rad = 3.14159265f);
// Torus around the z axis (major radius R, tube radius r); `arc_rad` < 2π gives an open arc
// starting at angle 0 around +x, counter-clockwise.
TriangleMesh makeTorus(float major_radius, float minor_radius, float arc_rad = 6.2831853f,
                       int segments = 32, int tube_segments = 12);
// Rectangle in the z = 0 plane centred at the origin, normal +z, split into a grid of
// cells of at most `max_cell` metres (keeps rasterised triangles small near the camera).
TriangleMesh makePlane(float size_x, float size_y, float max_cell = 0.5f);

// Appends `part` placed by `T_object_part` to `object`.
void addPart(TriangleMesh* object, TriangleMesh part, const Transform& T_object_part);

// Convenience poses for building composites.
Transform translation(float x, float y, float z);
Transform translationRotation(float x, float y, float z, const Eigen::Vector3d& axis,
                              double angle_rad);

}  // namespace objdb::sim
