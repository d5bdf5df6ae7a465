#include "core/completion/completion_score.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/str_format.h"

namespace objdb::completion {

std::vector<Eigen::Vector3f> addedVertices(const TriangleMesh& after, const MeshDistance& before) {
  std::vector<Eigen::Vector3f> added;
  for (const auto& v : after.vertices) {
    if (!(before.distance(v) <= before.maxDistance())) added.push_back(v);
  }
  return added;
}

FrameChecker::FrameChecker(std::vector<Eigen::Vector3f> points)
    : points_(std::move(points)), through_(points_.size(), 0), on_surface_(points_.size(), 0) {}

void FrameChecker::add(const Frame& frame, const Intrinsics& k) {
  const Eigen::Isometry3f T_camera_world = frame.T_world_camera.inverse().cast<float>();
  for (size_t i = 0; i < points_.size(); ++i) {
    const Eigen::Vector3f c = T_camera_world * points_[i];
    if (!(c.z() > 0.0f)) continue;
    const int u = int(std::lround(k.fx * c.x() / c.z() + k.cx));
    const int v = int(std::lround(k.fy * c.y() / c.z() + k.cy));
    if (u < 0 || v < 0 || u >= k.width || v >= k.height) continue;
    const float z = frame.depth.at(u, v);
    if (!isValidDepth(z)) continue;
    const float tolerance = std::max(0.03f, 0.02f * z);
    if (c.z() < z - tolerance) {
      ++through_[i];
    } else if (c.z() <= z + tolerance) {
      ++on_surface_[i];
    }
  }
}

FrameEvidence FrameChecker::evidence() const {
  FrameEvidence e;
  e.points = points_.size();
  for (size_t i = 0; i < points_.size(); ++i) {
    if (through_[i] > on_surface_[i]) {
      ++e.seen_through;
    } else if (on_surface_[i] > 0) {
      ++e.seen_on_surface;
    }
  }
  return e;
}

StatusOr<SurfaceGain> surfaceGain(const std::vector<TrueInstance>& instances,
                                  const std::map<std::string, const MeshDistance*>& before,
                                  const std::map<std::string, const MeshDistance*>& after,
                                  float tolerance_m) {
  std::map<std::string, int> kind_count;
  for (const auto& t : instances) {
    if (t.mesh == nullptr) {
      return absl::InvalidArgumentError(
          absl::StrFormat("completion score: instance %d of session %s has no mesh", t.id, t.session));
    }
    ++kind_count[t.kind];
  }
  for (const auto& [session, index] : before) {
    if (after.count(session) == 0) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "completion score: session %s has no completed reconstruction", session));
    }
  }
  auto within = [&](const MeshDistance* index, const Eigen::Vector3f& p) {
    return index->distance(p) <= tolerance_m;
  };
  SurfaceGain gain;
  for (size_t i = 0; i < instances.size(); ++i) {
    const TrueInstance& t = instances[i];
    if (kind_count[t.kind] < 2 || before.count(t.session) == 0) continue;
    OBJDB_ASSIGN_OR_RETURN(const auto samples, sampleSurface(*t.mesh, 0.01f));
    size_t b = 0, a = 0, c = 0;
    for (const auto& p : samples) {
      const Eigen::Vector3f w = t.T_world_object.cast<float>() * p;
      b += within(before.at(t.session), w) ? 1 : 0;
      a += within(after.at(t.session), w) ? 1 : 0;
      bool anywhere = false;
      for (const auto& other : instances) {
        if (anywhere) break;
        if (other.kind != t.kind || before.count(other.session) == 0) continue;
        if (other.mesh != t.mesh && other.mesh->vertices != t.mesh->vertices) continue;
        anywhere = within(before.at(other.session), other.T_world_object.cast<float>() * p);
      }
      c += anywhere ? 1 : 0;
    }
    const double n = double(std::max<size_t>(1, samples.size()));
    gain.instances.push_back({i, double(b) / n, double(a) / n, double(c) / n});
  }
  for (const auto& g : gain.instances) {
    gain.before += g.before;
    gain.after += g.after;
    gain.ceiling += g.ceiling;
  }
  if (!gain.instances.empty()) {
    const double n = double(gain.instances.size());
    gain.before /= n;
    gain.after /= n;
    gain.ceiling /= n;
  }
  return gain;
}

}  // namespace objdb::completion
