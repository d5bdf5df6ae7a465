#include "core/database/placements.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "absl/strings/str_format.h"

namespace objdb::database {

Eigen::AlignedBox3d Placement::worldBox() const {
  Eigen::AlignedBox3d out;
  for (int corner = 0; corner < 8; ++corner) {
    out.extend(T_world_object *
               bounds_object.corner(static_cast<Eigen::AlignedBox3d::CornerType>(corner)));
  }
  return out;
}

Status validateRegion(const Region& region) {
  if (region.box) {
    const char* axes[] = {"x", "y", "z"};
    for (int a = 0; a < 3; ++a) {
      const double lo = region.box->min()(a), hi = region.box->max()(a);
      if (!std::isfinite(lo) || !std::isfinite(hi)) {
        return absl::InvalidArgumentError(
            absl::StrFormat("box.min.%s / box.max.%s: not finite", axes[a], axes[a]));
      }
      if (lo > hi) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "box.min.%s %g > box.max.%s %g: min must not exceed max", axes[a], lo, axes[a], hi));
      }
    }
    return absl::OkStatus();
  }
  if (!region.centre.allFinite()) return absl::InvalidArgumentError("centre: not finite");
  if (!(std::isfinite(region.radius_m) && region.radius_m > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("radius_m: must be finite and > 0, got %g", region.radius_m));
  }
  return absl::OkStatus();
}

bool inRegion(const Placement& placement, const Region& region) {
  const Eigen::Vector3d c = placement.centre();
  if (region.box) return region.box->contains(c);
  return (c - region.centre).norm() <= region.radius_m;
}

namespace {

// The largest distance from a place in `from` to the nearest place in `to`.
double farthestFromNearest(const std::vector<Placement>& from, const std::vector<Placement>& to) {
  double worst = 0.0;
  for (const Placement& p : from) {
    double nearest = std::numeric_limits<double>::infinity();
    for (const Placement& q : to) nearest = std::min(nearest, (p.centre() - q.centre()).norm());
    worst = std::max(worst, nearest);
  }
  return worst;
}

}  // namespace

SessionChanges changesBetween(const std::vector<Placement>& first,
                              const std::vector<Placement>& second, double same_place_m) {
  std::map<int64_t, PlacementChange> by_model;
  for (const Placement& p : first) {
    by_model[p.model_id].model_id = p.model_id;
    by_model[p.model_id].before.push_back(p);
  }
  for (const Placement& p : second) {
    by_model[p.model_id].model_id = p.model_id;
    by_model[p.model_id].after.push_back(p);
  }
  SessionChanges out;
  for (auto& [id, change] : by_model) {
    if (change.before.empty()) {
      out.added.push_back(std::move(change));
    } else if (change.after.empty()) {
      out.removed.push_back(std::move(change));
    } else {
      // Both ways: a second copy placed, or one of two taken away, is a change too.
      change.moved_m = std::max(farthestFromNearest(change.after, change.before),
                                farthestFromNearest(change.before, change.after));
      if (change.moved_m > same_place_m) {
        out.moved.push_back(std::move(change));
      } else {
        ++out.unchanged;
      }
    }
  }
  return out;
}

}  // namespace objdb::database
