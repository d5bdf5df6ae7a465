#include "core/sim/renderer.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace objdb::sim {
namespace {
constexpr float kEdgeTolerance = 1e-5f;
}  // namespace

float boundingRadius(const TriangleMesh& mesh) {
  float r2 = 0.0f;
  for (const auto& v : mesh.vertices) r2 = std::max(r2, v.squaredNorm());
  return std::sqrt(r2);
}

Renderer::Renderer(const Intrinsics& intrinsics, const RenderParams& params)
    : intrinsics_(intrinsics), params_(params) {}

void Renderer::render(const std::vector<RenderInstance>& instances,
                      const Transform& T_world_camera, RenderOutput* out) const {
  const int w = intrinsics_.width, h = intrinsics_.height;
  out->depth = DepthImage(w, h, 0.0f);
  out->instances = InstanceImage(w, h, 0);
  out->cos_incidence = Image<float>(w, h, 0.0f);
  out->color = params_.render_color ? ColorImage(w, h, Rgb8{0, 0, 0}) : ColorImage();

  const Transform T_camera_world = T_world_camera.inverse();
  // Frustum half-angles for sphere culling.
  const float tan_left = float(intrinsics_.cx + 0.5) / float(intrinsics_.fx);
  const float tan_right = float(w - intrinsics_.cx + 0.5) / float(intrinsics_.fx);
  const float tan_top = float(intrinsics_.cy + 0.5) / float(intrinsics_.fy);
  const float tan_bottom = float(h - intrinsics_.cy + 0.5) / float(intrinsics_.fy);
  auto outside_plane = [](float x, float z, float tan_half, float r) {
    // Signed distance of (x, z) to the plane x = z · tan_half (outside when positive).
    return (x - z * tan_half) / std::sqrt(1.0f + tan_half * tan_half) > r;
  };

  std::vector<Eigen::Vector3f> camera_vertices;
  for (const auto& instance : instances) {
    if (instance.mesh == nullptr || instance.mesh->triangles.empty()) continue;
    const Eigen::Isometry3f T_camera_object = (T_camera_world * instance.T_world_object).cast<float>();
    const float radius =
        instance.bounding_radius > 0 ? instance.bounding_radius : boundingRadius(*instance.mesh);
    const Eigen::Vector3f c = T_camera_object.translation();
    if (c.z() + radius < params_.near_m || c.z() - radius > params_.far_m ||
        outside_plane(c.x(), c.z(), tan_right, radius) ||
        outside_plane(-c.x(), c.z(), tan_left, radius) ||
        outside_plane(c.y(), c.z(), tan_bottom, radius) ||
        outside_plane(-c.y(), c.z(), tan_top, radius)) {
      continue;
    }
    const auto& mesh = *instance.mesh;
    camera_vertices.resize(mesh.vertices.size());
    for (size_t i = 0; i < mesh.vertices.size(); ++i) camera_vertices[i] = T_camera_object * mesh.vertices[i];

    for (const auto& t : mesh.triangles) {
      const Eigen::Vector3f& a = camera_vertices[t[0]];
      const Eigen::Vector3f& b = camera_vertices[t[1]];
      const Eigen::Vector3f& cc = camera_vertices[t[2]];
      const Eigen::Vector3f n_raw = (b - a).cross(cc - a);
      const float n_len = n_raw.norm();
      if (!(n_len > 0.0f)) continue;
      const Eigen::Vector3f normal = n_raw / n_len;
      const int n_in = (a.z() >= params_.near_m) + (b.z() >= params_.near_m) + (cc.z() >= params_.near_m);
      if (n_in == 3) {
        rasterizeTriangle(a, b, cc, instance.instance_id, normal, instance.albedo, out);
        continue;
      }
      if (n_in == 0) continue;
      // Sutherland–Hodgman clip against z = near; yields a triangle or a quad.
      std::array<Eigen::Vector3f, 4> poly;
      int count = 0;
      const std::array<const Eigen::Vector3f*, 3> in = {&a, &b, &cc};
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3f& p = *in[k];
        const Eigen::Vector3f& q = *in[(k + 1) % 3];
        const bool p_in = p.z() >= params_.near_m, q_in = q.z() >= params_.near_m;
        if (p_in) poly[count++] = p;
        if (p_in != q_in) {
          const float s = (params_.near_m - p.z()) / (q.z() - p.z());
          poly[count++] = p + s * (q - p);
        }
      }
      for (int k = 1; k + 1 < count; ++k) {
        rasterizeTriangle(poly[0], poly[k], poly[k + 1], instance.instance_id, normal,
                          instance.albedo, out);
      }
    }
  }
}

void Renderer::rasterizeTriangle(const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                                 const Eigen::Vector3f& c, uint16_t id,
                                 const Eigen::Vector3f& normal, const Rgb8& albedo,
                                 RenderOutput* out) const {
  const float fx = float(intrinsics_.fx), fy = float(intrinsics_.fy);
  const float cx = float(intrinsics_.cx), cy = float(intrinsics_.cy);
  const int w = intrinsics_.width, h = intrinsics_.height;
  // Screen positions and inverse depths (1/z is affine in screen space for a planar triangle).
  const float ia = 1.0f / a.z(), ib = 1.0f / b.z(), ic = 1.0f / c.z();
  const float ua = fx * a.x() * ia + cx, va = fy * a.y() * ia + cy;
  const float ub = fx * b.x() * ib + cx, vb = fy * b.y() * ib + cy;
  const float uc = fx * c.x() * ic + cx, vc = fy * c.y() * ic + cy;
  const float area = (ub - ua) * (vc - va) - (vb - va) * (uc - ua);
  if (!(std::abs(area) > 1e-12f)) return;
  const int u0 = std::max(0, int(std::ceil(std::min({ua, ub, uc}))));
  const int u1 = std::min(w - 1, int(std::floor(std::max({ua, ub, uc}))));
  const int v0 = std::max(0, int(std::ceil(std::min({va, vb, vc}))));
  const int v1 = std::min(h - 1, int(std::floor(std::max({va, vb, vc}))));
  if (u0 > u1 || v0 > v1) return;
  const float inv_area = 1.0f / area;
  // Barycentric weights as affine functions of (u, v): w_a = (A_a u + B_a v + C_a) / area.
  const float Aa = (vb - vc), Ba = (uc - ub), Ca = ub * vc - uc * vb;
  const float Ab = (vc - va), Bb = (ua - uc), Cb = uc * va - ua * vc;
  // Plane of the triangle through the camera centre: depth along a ray is −d / (n · ray).
  const float n_dot_a = normal.dot(a);
  for (int v = v0; v <= v1; ++v) {
    const float ry = (float(v) - cy) / fy;
    for (int u = u0; u <= u1; ++u) {
      const float wa = (Aa * u + Ba * v + Ca) * inv_area;
      const float wb = (Ab * u + Bb * v + Cb) * inv_area;
      const float wc = 1.0f - wa - wb;
      // A small tolerance closes cracks along edges shared by two triangles, where rounding can
      // put a pixel centre just outside both; the z-buffer makes the overlap harmless.
      if (wa < -kEdgeTolerance || wb < -kEdgeTolerance || wc < -kEdgeTolerance) continue;
      const float rx = (float(u) - cx) / fx;
      const float denom = normal.x() * rx + normal.y() * ry + normal.z();
      // Exact ray–plane depth where it is well conditioned, affine 1/z otherwise (grazing).
      float z = std::abs(denom) > 1e-6f ? n_dot_a / denom : 1.0f / (wa * ia + wb * ib + wc * ic);
      if (!(z >= params_.near_m && z <= params_.far_m)) continue;
      const size_t idx = size_t(v) * size_t(w) + size_t(u);
      float& zbuf = out->depth.data[idx];
      if (zbuf != 0.0f && zbuf <= z) continue;
      zbuf = z;
      out->instances.data[idx] = id;
      const float ray_norm = std::sqrt(rx * rx + ry * ry + 1.0f);
      const float cos_inc = std::min(1.0f, std::abs(denom) / ray_norm);
      out->cos_incidence.data[idx] = cos_inc;
      if (!out->color.empty()) {
        const float shade = params_.ambient + (1.0f - params_.ambient) * cos_inc;
        out->color.data[idx] = Rgb8{uint8_t(std::min(255.0f, albedo.r * shade)),
                                    uint8_t(std::min(255.0f, albedo.g * shade)),
                                    uint8_t(std::min(255.0f, albedo.b * shade))};
      }
    }
  }
}

}  // namespace objdb::sim
