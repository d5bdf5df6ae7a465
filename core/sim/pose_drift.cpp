#include "core/sim/pose_drift.h"

#include <algorithm>
#include <cmath>

#include "core/sim/noise.h"

namespace objdb::sim {
namespace {
constexpr double kPi = 3.14159265358979323846;
// "Frame" key of the drift's phase draws: apart from the frame indices the depth noise uses, so
// a drift seed equal to the noise seed does not reuse its draws.
constexpr uint64_t kDriftKey = 0x6472696674ULL;  // "drift"
}  // namespace

Status PoseDrift::validate() const {
  // Bounds: a tracker that is off by a metre or ten degrees has lost track, not drifted.
  if (!(std::isfinite(translation_m) && translation_m >= 0.0f && translation_m <= 1.0f)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("drift.translation_m must be in [0, 1] metres (got %g)", translation_m));
  }
  if (!(std::isfinite(rotation_deg) && rotation_deg >= 0.0f && rotation_deg <= 10.0f)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("drift.rotation_deg must be in [0, 10] degrees (got %g)", rotation_deg));
  }
  return absl::OkStatus();
}

DriftAt driftAt(const PoseDrift& drift, size_t index, size_t frames) {
  DriftAt d;
  if (!drift.enabled() || frames < 2) return d;
  const double s = std::min(1.0, double(index) / double(frames - 1));  // 0 → 1 along the path
  double phase[6];
  for (int k = 0; k < 6; ++k) phase[k] = 2 * kPi * uniform01(drift.seed, kDriftKey, 0, k);
  // Translation: the magnitude ramps with s (wobbling between 0.7 and 1 of the ramp), its
  // direction turns slowly and stays mostly horizontal.
  const double t_norm =
      drift.translation_m * s * (0.85 + 0.15 * std::sin(2 * kPi * 1.3 * s + phase[0]));
  const double heading = phase[1] + 2 * kPi * 0.6 * s;
  const double elevation = 0.35 * std::sin(2 * kPi * 0.8 * s + phase[2]);
  d.translation = t_norm * Eigen::Vector3d(std::cos(elevation) * std::cos(heading),
                                           std::cos(elevation) * std::sin(heading),
                                           std::sin(elevation));
  // Rotation: mostly about gravity (a tracker with an IMU observes roll and pitch, not yaw).
  const double r_rad = drift.rotation_deg * kPi / 180.0 * s *
                       (0.85 + 0.15 * std::sin(2 * kPi * 1.1 * s + phase[3]));
  const double tilt = phase[4] + 2 * kPi * 0.5 * s;
  const double yaw_sign = phase[5] < kPi ? 1.0 : -1.0;
  const Eigen::Vector3d axis =
      Eigen::Vector3d(0.35 * std::cos(tilt), 0.35 * std::sin(tilt), yaw_sign).normalized();
  d.rotation = Eigen::AngleAxisd(r_rad, axis).toRotationMatrix();
  return d;
}

Transform driftedPose(const PoseDrift& drift, const Transform& T_world_camera, size_t index,
                      size_t frames) {
  if (!drift.enabled()) return T_world_camera;
  const DriftAt d = driftAt(drift, index, frames);
  Transform T = T_world_camera;
  T.translation() += d.translation;
  T.linear() = d.rotation * T_world_camera.linear();
  return T;
}

}  // namespace objdb::sim
