#include "core/sim/shapes.h"

#include <algorithm>
#include <cmath>

namespace objdb::sim {
namespace {
constexpr float kPi = 3.14159265358979f;

int addVertex(TriangleMesh* m, float x, float y, float z) {
  m->vertices.emplace_back(x, y, z);
  return static_cast<int>(m->vertices.size()) - 1;
}
void addTri(TriangleMesh* m, int a, int b, int c) { m->triangles.emplace_back(a, b, c); }
void addQuad(TriangleMesh* m, int a, int b, int c, int d) {  // counter-clockwise a b c d
  addTri(m, a, b, c);
  addTri(m, a, c, d);
}
// Disc at height z facing up (+z) or down, as a fan around a centre vertex.
void addDisc(TriangleMesh* m, float radius, float z, int segments, bool up) {
  const int centre = addVertex(m, 0, 0, z);
  const int first = static_cast<int>(m->vertices.size());
  for (int i = 0; i < segments; ++i) {
    const float a = 2 * kPi * i / segments;
    addVertex(m, radius * std::cos(a), radius * std::sin(a), z);
  }
  for (int i = 0; i < segments; ++i) {
    const int a = first + i, b = first + (i + 1) % segments;
    if (up) {
      addTri(m, centre, a, b);
    } else {
      addTri(m, centre, b, a);
    }
  }
}
}  // namespace

TriangleMesh makeBox(const Eigen::Vector3f& size) {
  TriangleMesh m;
  const Eigen::Vector3f h = size / 2;
  for (int i = 0; i < 8; ++i) {
    addVertex(&m, (i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? h.z() : -h.z());
  }
  addQuad(&m, 0, 2, 3, 1);  // -z
  addQuad(&m, 4, 5, 7, 6);  // +z
  addQuad(&m, 0, 1, 5, 4);  // -y
  addQuad(&m, 2, 6, 7, 3);  // +y
  addQuad(&m, 0, 4, 6, 2);  // -x
  addQuad(&m, 1, 3, 7, 5);  // +x
  return m;
}

TriangleMesh makeCylinder(float radius, float height, int segments) {
  TriangleMesh m;
  for (int i = 0; i < segments; ++i) {
    const float a = 2 * kPi * i / segments;
    addVertex(&m, radius * std::cos(a), radius * std::sin(a), 0);
    addVertex(&m, radius * std::cos(a), radius * std::sin(a), height);
  }
  for (int i = 0; i < segments; ++i) {
    const int j = (i + 1) % segments;
    addQuad(&m, 2 * i, 2 * j, 2 * j + 1, 2 * i + 1);
  }
  addDisc(&m, radius, 0, segments, false);
  addDisc(&m, radius, height, segments, true);
  return m;
}

TriangleMesh makeCone(float radius, float height, int segments) {
  TriangleMesh m;
  const int apex = addVertex(&m, 0, 0, height);
  for (int i = 0; i < segments; ++i) {
    const float a = 2 * kPi * i / segments;
    addVertex(&m, radius * std::cos(a), radius * std::sin(a), 0);
  }
  for (int i = 0; i < segments; ++i) addTri(&m, apex, 1 + i, 1 + (i + 1) % segments);
  addDisc(&m, radius, 0, segments, false);
  return m;
}

TriangleMesh makeSphere(float radius, int rings, int segments, float max_polar_rad) {
  TriangleMesh m;
  const float max_polar = std::clamp(max_polar_rad, 0.01f, kPi);
  const bool closed = max_polar >= kPi - 1e-4f;
  const int north = addVertex(&m, 0, 0, radius);
  const int last_ring = closed ? rings - 1 : rings;
  for (int r = 1; r <= last_ring; ++r) {
    const float polar = max_polar * r / rings;
    for (int s = 0; s < segments; ++s) {
      const float a = 2 * kPi * s / segments;
      addVertex(&m, radius * std::sin(polar) * std::cos(a), radius * std::sin(polar) * std::sin(a),
                radius * std::cos(polar));
    }
  }
  auto ring_vertex = [&](int r, int s) { return 1 + (r - 1) * segments + (s % segments); };
  for (int s = 0; s < segments; ++s) addTri(&m, north, ring_vertex(1, s), ring_vertex(1, s + 1));
  for (int r = 1; r < last_ring; ++r) {
    for (int s = 0; s < segments; ++s) {
      addQuad(&m, ring_vertex(r, s), ring_vertex(r + 1, s), ring_vertex(r + 1, s + 1),
              ring_vertex(r, s + 1));
    }
  }
  if (closed) {
    const int south = addVertex(&m, 0, 0, -radius);
    for (int s = 0; s < segments; ++s) {
      addTri(&m, south, ring_vertex(last_ring, s + 1), ring_vertex(last_ring, s));
    }
  }
  return m;
}

TriangleMesh makeTorus(float major_radius, float minor_radius, float arc_rad, int segments,
                       int tube_segments) {
  TriangleMesh m;
  const bool full = arc_rad >= 2 * kPi - 1e-4f;
  const int rings = full ? segments : segments + 1;
  for (int i = 0; i < rings; ++i) {
    const float a = (full ? 2 * kPi : arc_rad) * i / segments;
    for (int j = 0; j < tube_segments; ++j) {
      const float b = 2 * kPi * j / tube_segments;
      const float rr = major_radius + minor_radius * std::cos(b);
      addVertex(&m, rr * std::cos(a), rr * std::sin(a), minor_radius * std::sin(b));
    }
  }
  auto v = [&](int i, int j) { return (i % rings) * tube_segments + (j % tube_segments); };
  for (int i = 0; i < segments; ++i) {
    for (int j = 0; j < tube_segments; ++j) {
      addQuad(&m, v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
    }
  }
  if (!full) {  // close both ends of the arc with fans
    for (int end = 0; end < 2; ++end) {
      const int ring = end == 0 ? 0 : rings - 1;
      const float a = end == 0 ? 0.0f : arc_rad;
      const int centre = addVertex(&m, major_radius * std::cos(a), major_radius * std::sin(a), 0);
      for (int j = 0; j < tube_segments; ++j) {
        if (end == 0) {
          addTri(&m, centre, v(ring, j + 1), v(ring, j));
        } else {
          addTri(&m, centre, v(ring, j), v(ring, j + 1));
        }
      }
    }
  }
  return m;
}

TriangleMesh makePlane(float size_x, float size_y, float max_cell) {
  TriangleMesh m;
  const int nx = std::max(1, static_cast<int>(std::ceil(size_x / max_cell)));
  const int ny = std::max(1, static_cast<int>(std::ceil(size_y / max_cell)));
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      addVertex(&m, -size_x / 2 + size_x * i / nx, -size_y / 2 + size_y * j / ny, 0);
    }
  }
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const int a = j * (nx + 1) + i;
      addQuad(&m, a, a + 1, a + nx + 2, a + nx + 1);
    }
  }
  return m;
}

void addPart(TriangleMesh* object, TriangleMesh part, const Transform& T_object_part) {
  part.transform(T_object_part);
  object->append(part);
}

Transform translation(float x, float y, float z) {
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(x, y, z);
  return T;
}

Transform translationRotation(float x, float y, float z, const Eigen::Vector3d& axis,
                              double angle_rad) {
  Transform T = translation(x, y, z);
  T.linear() = Eigen::AngleAxisd(angle_rad, axis.normalized()).toRotationMatrix();
  return T;
}

}  // namespace objdb::sim
