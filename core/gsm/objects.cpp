#include "core/gsm/objects.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <numeric>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "core/common/grid_key.h"
#include "core/common/plane_spans.h"

namespace objdb::gsm {
namespace {

uint64_t packPair(Label a, Label b) {
  return a < b ? (uint64_t(a) << 32) | b : (uint64_t(b) << 32) | a;
}

// A label's shape: voxel moments and their principal axes.
struct Shape {
  int64_t n = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d outer = Eigen::Matrix3d::Zero();
  // Derived.
  Eigen::Vector3f centroid = Eigen::Vector3f::Zero();
  Eigen::Vector3f normal = Eigen::Vector3f::UnitZ();  // thinnest axis, towards the observed side
  Eigen::Vector3f axis[2] = {Eigen::Vector3f::UnitX(), Eigen::Vector3f::UnitY()};  // in-plane
  float extent[2] = {0.0f, 0.0f};  // along axis[]: √12·σ (a uniform slab's width)
  float thickness = 0.0f;          // σ along the normal, voxels
  bool planar = false;
  bool structure = false;
};

// The voxels of two touching labels next to each other (each side's own voxels).
// Two touching labels: the voxels of each next to the other (side[0]: the smaller label's), and
// how many there are on both sides together.
struct Contact {
  int64_t pairs = 0;
  std::vector<tsdf::VoxelIndex> side[2];
};

// The main label of a voxel (0: none), with the layer's block arithmetic.
class LabelLookup {
 public:
  LabelLookup(const LabelBlocks& labels, const tsdf::TsdfLayer& layer)
      : labels_(labels), layer_(layer) {}
  Label at(const tsdf::VoxelIndex& v) const {
    const auto it = labels_.find(layer_.blockOfVoxel(v));
    return it == labels_.end() ? 0 : it->second[layer_.linearInBlock(v)];
  }

 private:
  const LabelBlocks& labels_;
  const tsdf::TsdfLayer& layer_;
};

// Orients `shape.normal` towards the side the TSDF is positive on (free space, where the camera
// looked from), from the distance difference across the surface at up to 256 of its voxels.
void orientNormal(const tsdf::TsdfLayer& layer, const std::vector<tsdf::VoxelIndex>& voxels,
                  Shape* shape) {
  const float step = 1.5f;  // voxels
  double vote = 0.0;
  const size_t stride = std::max<size_t>(1, voxels.size() / 256);
  for (size_t i = 0; i < voxels.size(); i += stride) {
    const Eigen::Vector3f c = voxels[i].cast<float>();
    const auto front = layer.voxel((c + step * shape->normal).array().round().cast<int>().matrix());
    const auto back = layer.voxel((c - step * shape->normal).array().round().cast<int>().matrix());
    if (front == nullptr || back == nullptr || !(front->weight > 0) || !(back->weight > 0)) continue;
    vote += double(front->distance - back->distance);
  }
  if (vote < 0.0) shape->normal = -shape->normal;
}

void deriveShape(float voxel, Shape* s) {
  const double n = double(s->n);
  const Eigen::Vector3d mean = s->sum / n;
  const Eigen::Matrix3d cov = s->outer / n - mean * mean.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);  // ascending eigenvalues
  const Eigen::Vector3d sigma = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt() * double(voxel);
  s->centroid = mean.cast<float>();  // voxel units
  s->normal = eig.eigenvectors().col(0).cast<float>();
  s->axis[0] = eig.eigenvectors().col(2).cast<float>();
  s->axis[1] = eig.eigenvectors().col(1).cast<float>();
  s->extent[0] = float(std::sqrt(12.0) * sigma(2));
  s->extent[1] = float(std::sqrt(12.0) * sigma(1));
  s->thickness = float(sigma(0) / double(voxel));
  s->planar = s->n >= 20 && sigma(0) <= std::max(1.5 * double(voxel), 0.1 * sigma(1));
}

// The largest full span (metres) of `voxels` along the principal axes of `shape`.
float fullSpan(const Shape& shape, const std::vector<const std::vector<tsdf::VoxelIndex>*>& voxels,
               float voxel) {
  const Eigen::Vector3f axes[3] = {shape.normal, shape.axis[0], shape.axis[1]};
  float lo[3] = {1e30f, 1e30f, 1e30f}, hi[3] = {-1e30f, -1e30f, -1e30f};
  for (const auto* list : voxels) {
    for (const auto& v : *list) {
      const Eigen::Vector3f p = v.cast<float>();
      for (int a = 0; a < 3; ++a) {
        const float x = p.dot(axes[a]);
        lo[a] = std::min(lo[a], x);
        hi[a] = std::max(hi[a], x);
      }
    }
  }
  float span = 0.0f;
  for (int a = 0; a < 3; ++a) span = std::max(span, hi[a] - lo[a] + 1.0f);
  return span * voxel;
}

// Whether `upper` rests on planar `support` at their contact (`contact` = the support's voxels
// next to `upper`): `upper` lies on the support's observed side, and the support's surface
// continues beyond the contact along ±both in-plane axes within `probe` voxels, or along three of
// them when the contact is a small footprint on it (at most half its extent along both axes: the
// fourth side may lie in the object's shadow, never seen from where the camera went).
bool restsOn(const Shape& upper, const Shape& support_shape,
             const std::vector<tsdf::VoxelIndex>& support_voxels,
             const std::vector<tsdf::VoxelIndex>& contact, Label support_label,
             const LabelLookup& lookup, const tsdf::TsdfLayer& layer, float probe, float voxel) {
  if (contact.empty()) return false;
  Eigen::Vector3f c = Eigen::Vector3f::Zero();
  for (const auto& v : contact) c += v.cast<float>();
  c /= float(contact.size());
  // The support's plane: the whole label's when it is planar, else the label's surface around
  // the contact, 5 voxels beyond it (a table top with its apron and legs under one label is flat
  // where a mug stands).
  Shape local;
  if (!support_shape.planar) {
    float radius = 0.0f;
    for (const auto& v : contact) radius = std::max(radius, (v.cast<float>() - c).norm());
    radius += 5.0f;  // voxels: the surface just around the contact
    std::vector<tsdf::VoxelIndex> near;
    for (const auto& v : support_voxels) {
      if ((v.cast<float>() - c).squaredNorm() <= radius * radius) near.push_back(v);
    }
    for (const auto& v : near) {
      const Eigen::Vector3d p = v.cast<double>();
      ++local.n;
      local.sum += p;
      local.outer += p * p.transpose();
    }
    if (local.n < 20) return false;
    deriveShape(voxel, &local);
    if (!local.planar) return false;
    orientNormal(layer, near, &local);
  }
  const Shape& support = support_shape.planar ? support_shape : local;
  if ((upper.centroid - c).dot(support.normal) <= 0.0f) return false;  // behind it: attached
  int sides = 0;
  bool small = true;
  for (int axis = 0; axis < 2; ++axis) {
    float lo = 0.0f, hi = 0.0f;  // the contact's own extent along the axis
    for (const auto& v : contact) {
      const float x = (v.cast<float>() - c).dot(support.axis[axis]);
      lo = std::min(lo, x);
      hi = std::max(hi, x);
    }
    small = small && (hi - lo + 1.0f) * voxel <= 0.5f * support.extent[axis];
    for (const float sign : {1.0f, -1.0f}) {
      const Eigen::Vector3f dir = sign * support.axis[axis];
      const float reach = sign > 0 ? hi : -lo;
      bool found = false;
      for (float s = reach + 1.0f; s <= reach + probe && !found; s += 1.0f) {
        const Eigen::Vector3f q = c + s * dir;
        for (const float t : {0.0f, 1.0f, -1.0f, 2.0f, -2.0f}) {
          const tsdf::VoxelIndex v = (q + t * support.normal).array().round().cast<int>().matrix();
          if (lookup.at(v) == support_label) {
            found = true;
            break;
          }
        }
      }
      sides += found ? 1 : 0;
    }
  }
  return sides == 4 || (sides == 3 && small);
}

// The extent of `labels`' voxels (voxel units, lowest and highest) along the two in-plane axes
// of `plane`.
struct PlaneExtent {
  float lo[2] = {1e30f, 1e30f}, hi[2] = {-1e30f, -1e30f};
};
PlaneExtent extentAlong(const Shape& plane, const std::vector<Label>& labels,
                        const absl::flat_hash_map<Label, std::vector<tsdf::VoxelIndex>>& voxels_of) {
  PlaneExtent e;
  for (const Label l : labels) {
    const auto found = voxels_of.find(l);
    if (found == voxels_of.end()) continue;
    for (const auto& v : found->second) {
      for (int a = 0; a < 2; ++a) {
        const float x = v.cast<float>().dot(plane.axis[a]);
        e.lo[a] = std::min(e.lo[a], x);
        e.hi[a] = std::max(e.hi[a], x);
      }
    }
  }
  return e;
}

// The 26 voxels around a voxel.
const std::array<Eigen::Vector3i, 26>& neighbours26() {
  static const std::array<Eigen::Vector3i, 26> offsets = [] {
    std::array<Eigen::Vector3i, 26> o;
    size_t n = 0;
    for (int z = -1; z <= 1; ++z) {
      for (int y = -1; y <= 1; ++y) {
        for (int x = -1; x <= 1; ++x) {
          if (x != 0 || y != 0 || z != 0) o[n++] = Eigen::Vector3i(x, y, z);
        }
      }
    }
    return o;
  }();
  return offsets;
}

// The voxels of structure label `structure` standing off its plane that objects take (see
// objects.h), appended to out->annexed / annexed_part. `out` has members and object_of already.
void annexFrom(Label structure, const Shape& plane, const std::vector<tsdf::VoxelIndex>& voxels,
               const absl::flat_hash_map<Label, std::vector<tsdf::VoxelIndex>>& voxels_of,
               const LabelLookup& lookup, const tsdf::TsdfLayer& layer,
               const std::vector<Eigen::Vector3i>& touching, float max_height,
               const std::vector<Label>& floating, int min_island, ObjectGroups* out) {
  // Heights of the surface each voxel holds above the plane, in voxels: the voxel centre's less
  // its TSDF distance (the surface lies that far below a voxel on the observed side), so the
  // lattice does not quantise them. A floor's own voxels are then at its noise, a base disc 3 cm
  // above it at 1.5 voxels (2 cm), whichever layers of voxels the floor falls into.
  const float inv = 1.0f / layer.voxelSize();
  std::vector<float> heights(voxels.size(), 0.0f);
  double sum = 0.0, sum2 = 0.0;
  for (size_t i = 0; i < voxels.size(); ++i) {
    const tsdf::TsdfVoxel* t = layer.voxel(voxels[i]);
    const float d = t != nullptr && t->weight > 0.0f ? t->distance * inv : 0.0f;
    heights[i] = (voxels[i].cast<float>() - plane.centroid).dot(plane.normal) - d;
    sum += heights[i];
    sum2 += double(heights[i]) * heights[i];
  }
  if (voxels.empty()) return;
  const double mean = sum / double(voxels.size());
  const float spread = float(std::sqrt(std::max(0.0, sum2 / double(voxels.size()) - mean * mean)));
  const float min_height = std::max(1.0f, 2.0f * spread);
  if (max_height <= min_height) return;
  absl::flat_hash_set<uint64_t> off;
  std::vector<tsdf::VoxelIndex> candidates;
  for (size_t i = 0; i < voxels.size(); ++i) {
    const float h = heights[i] - float(mean);
    if (h > min_height && h <= max_height) {
      off.insert(packGridKey(voxels[i]));
      candidates.push_back(voxels[i]);
    }
  }
  if (candidates.empty()) return;
  // Each object's footprint on the plane (voxels), computed when first needed.
  absl::flat_hash_map<Label, PlaneExtent> footprints;
  const auto inside = [&](Label object, const tsdf::VoxelIndex& v) {
    auto it = footprints.find(object);
    if (it == footprints.end()) {
      it = footprints.emplace(object, extentAlong(plane, out->members.at(object), voxels_of)).first;
    }
    const PlaneExtent& box = it->second;
    for (int a = 0; a < 2; ++a) {
      const float x = v.cast<float>().dot(plane.axis[a]);
      if (x < box.lo[a] - 1.0f || x > box.hi[a] + 1.0f) return false;
    }
    return true;
  };
  // Breadth first from every off-plane voxel next to an object's voxel, all at once.
  absl::flat_hash_map<uint64_t, Label> part_of;
  std::vector<std::pair<tsdf::VoxelIndex, Label>> queue;
  for (const auto& v : candidates) {
    for (const Eigen::Vector3i& o : touching) {
      const Label l = lookup.at(v + o);
      if (l == 0 || l == structure || out->structure.contains(l)) continue;
      if (!inside(out->object_of.at(l), v)) continue;
      part_of.emplace(packGridKey(v), l);
      queue.emplace_back(v, l);
      break;
    }
  }
  for (size_t head = 0; head < queue.size(); ++head) {
    const auto [v, part] = queue[head];
    const Label object = out->object_of.at(part);
    for (const Eigen::Vector3i& o : neighbours26()) {
      const tsdf::VoxelIndex n = v + o;
      const uint64_t key = packGridKey(n);
      if (!off.contains(key) || part_of.contains(key) || !inside(object, n)) continue;
      part_of.emplace(key, part);
      queue.emplace_back(n, part);
    }
  }
  // Islands: the off-plane voxels no object reached, in connected pieces. A piece under an object
  // that floats above the annexed band (see objects.h) is its foot: a pedestal chair's base when
  // the column between them carries no label. Its voxels inside the footprint of the floating
  // object whose footprint holds most of it (at least half) join that object, as the part nearest
  // the plane.
  if (!floating.empty()) {
    // A floating object's lowest voxel above the plane and the member label holding it, computed
    // when an island first asks.
    absl::flat_hash_map<Label, std::pair<float, Label>> lowest_of;
    const auto lowest = [&](Label object) -> const std::pair<float, Label>& {
      auto it = lowest_of.find(object);
      if (it != lowest_of.end()) return it->second;
      std::pair<float, Label> low{1e30f, 0};
      for (const Label l : out->members.at(object)) {
        for (const auto& v : voxels_of.at(l)) {
          const float h = (v.cast<float>() - plane.centroid).dot(plane.normal) - float(mean);
          if (h < low.first) low = {h, l};
        }
      }
      return lowest_of.emplace(object, low).first->second;
    };
    absl::flat_hash_set<uint64_t> seen;
    for (const auto& start : candidates) {
      if (part_of.contains(packGridKey(start)) || !seen.insert(packGridKey(start)).second) continue;
      std::vector<tsdf::VoxelIndex> island{start};
      for (size_t head = 0; head < island.size(); ++head) {
        for (const Eigen::Vector3i& o : neighbours26()) {
          const tsdf::VoxelIndex n = island[head] + o;
          const uint64_t key = packGridKey(n);
          if (!off.contains(key) || part_of.contains(key) || !seen.insert(key).second) continue;
          island.push_back(n);
        }
      }
      if (int(island.size()) < min_island) continue;
      Label best = 0;
      size_t best_inside = 0;
      for (const Label object : floating) {
        if (lowest(object).first <= max_height) continue;  // not above the band
        size_t n = 0;
        for (const auto& v : island) n += inside(object, v) ? 1 : 0;
        if (2 * n >= island.size() && n > best_inside) {
          best = object;
          best_inside = n;
        }
      }
      if (best == 0) continue;
      const Label part = lowest(best).second;
      for (const auto& v : island) {
        if (!inside(best, v)) continue;  // the footprint bounds what an object takes
        part_of.emplace(packGridKey(v), part);
        queue.emplace_back(v, part);
      }
      ++out->islands;
    }
  }
  for (const auto& [v, part] : queue) {
    out->annexed[out->object_of.at(part)].push_back({v, part});
    out->annexed_part[packGridKey(v)] = part;
  }
}

// Shadow contacts (see objects.h): every label standing on a structure (touching it, on its
// observed side; the structure it touches most) is probed from each of its voxels straight along
// that structure's normal, up to `steps` voxels. The probe stops at the label's own voxels, at
// observed free space (TSDF distance at least a voxel), at structure, and at another label; it
// counts that label when it got there farther than `touching` voxels (nearer, they touch: the
// contacts and the support rule decided), through at least one voxel no camera observed, and
// when that label's object floats (`floating`: as grouped so far it neither touches structure
// nor rests on a support, so something unseen must carry it). Labels with at least `min_hits`
// such probes between them are united. A desk stands on its own legs: a chair pushed under it,
// its armrests a few centimetres below the top, stays apart.
template <typename Floating, typename Unite>
void joinAcrossShadows(const absl::flat_hash_map<Label, Shape>& shapes,
                       const absl::flat_hash_map<Label, std::vector<tsdf::VoxelIndex>>& voxels_of,
                       const absl::flat_hash_map<uint64_t, int64_t>& touches_structure,
                       const LabelLookup& lookup, const tsdf::TsdfLayer& layer, int touching,
                       int steps, int min_hits, const Floating& floating, ObjectGroups* out,
                       const Unite& unite) {
  // Each label's structure, in label order.
  std::map<Label, std::pair<int64_t, Label>> standing_on;  // label → (voxels touching, structure)
  for (const auto& [key, count] : touches_structure) {
    const Label l = Label(key >> 32), m = Label(key & 0xffffffffULL);
    if (count < min_hits) continue;
    const Shape& floor = shapes.at(m);
    if ((shapes.at(l).centroid - floor.centroid).dot(floor.normal) <= 0.0f) continue;
    auto [it, fresh] = standing_on.try_emplace(l, count, m);
    if (!fresh &&
        (count > it->second.first || (count == it->second.first && m < it->second.second))) {
      it->second = {count, m};
    }
  }
  const float voxel = layer.voxelSize();
  std::map<uint64_t, int> hits;  // packPair → probes
  for (const auto& [l, on] : standing_on) {
    const Eigen::Vector3f up = shapes.at(on.second).normal;
    for (const tsdf::VoxelIndex& v : voxels_of.at(l)) {
      bool unobserved = false;
      for (int k = 1; k <= steps; ++k) {
        const tsdf::VoxelIndex q =
            (v.cast<float>() + float(k) * up).array().round().cast<int>().matrix();
        const Label m = lookup.at(q);
        if (m == l) break;
        if (m != 0) {
          if (k > touching && unobserved && !out->structure.contains(m) && floating(m)) {
            ++hits[packPair(l, m)];
          }
          break;
        }
        const tsdf::TsdfVoxel* t = layer.voxel(q);
        if (t != nullptr && t->weight > 0.0f) {
          if (t->distance >= voxel) break;  // seen free
        } else {
          unobserved = true;
        }
      }
    }
  }
  for (const auto& [key, n] : hits) {
    if (n < min_hits) continue;
    unite(Label(key >> 32), Label(key & 0xffffffffULL));
    ++out->shadow_joins;
  }
}

Label findRoot(absl::flat_hash_map<Label, Label>* parent, Label l) {
  Label root = l;
  while ((*parent)[root] != root) root = (*parent)[root];
  while ((*parent)[l] != root) {
    const Label next = (*parent)[l];
    (*parent)[l] = root;
    l = next;
  }
  return root;
}

// Parts standing on the floor (ours): with an up direction and a floor, a label whose lowest
// voxel lies within the floor's band (and two voxels: the cut takes the floor's own voxels from
// it) stands on the floor, as a chair's or a table's leg does. A part carries another it touches
// when the contact lies in the top quarter of its height above the floor: legs carry the seat
// they end under, a table's legs its apron. Other contacts (a seat against a table's leg, a
// seat's edge under a table top, a back on a seat) are decided by units: the parts joined by
// carrying, which stand when any of their parts does.
struct StandingParts {
  bool known = false;  // up and a floor were found
  Eigen::Vector3f up = Eigen::Vector3f::UnitZ();
  float floor_m = 0.0f, reach_m = 0.0f, voxel = 0.0f;
  absl::flat_hash_map<Label, std::pair<float, float>> height;  // label → lowest, highest (m)
  // On the floor's plane (axes across up): every label's footprint (the box of its voxels),
  // centre and voxel count.
  Eigen::Vector3f across[2] = {Eigen::Vector3f::UnitX(), Eigen::Vector3f::UnitY()};
  absl::flat_hash_map<Label, Eigen::AlignedBox2f> footprint;
  absl::flat_hash_map<Label, Eigen::Vector2f> centre2d;
  absl::flat_hash_map<Label, size_t> voxels;

  bool stands(Label l) const {
    const auto it = height.find(l);
    return it != height.end() && it->second.first <= floor_m + reach_m;
  }
  float heightOf(const tsdf::VoxelIndex& v) const {
    return up.dot((v.cast<float>() + Eigen::Vector3f::Constant(0.5f)) * voxel);
  }
  // Whether one of a, b stands and carries the other at their contact.
  bool carries(Label a, Label b, const Contact& c) const {
    if (stands(a) && stands(b)) return oneBase(a, b, c);
    if (stands(a) == stands(b)) return false;
    return atTop(stands(a) ? a : b, c);
  }
  // Two standing parts are one base when the smaller stands under the other's footprint (a leg
  // the segmenter cut from its chair or from a cow's body), or when the lower carries the higher
  // at its top; a chair beside a table stands apart. The smaller of the two joins one base
  // only (the one it touches most, decided by the caller): a crumb of a chair's leg tucked
  // under a table lies under both footprints.
  bool oneBase(Label a, Label b, const Contact& c) const {
    if (under(a, b)) return true;
    const Label lower = height.at(a).second <= height.at(b).second ? a : b;
    return atTop(lower, c);
  }
  Label smaller(Label a, Label b) const { return voxels.at(a) <= voxels.at(b) ? a : b; }
  // Whether the smaller of a, b (in voxels) has its centre over the other's footprint.
  bool under(Label a, Label b) const {
    const Label small = smaller(a, b), big = small == a ? b : a;
    const auto& box = footprint.at(big);
    const Eigen::Vector2f centre = centre2d.at(small);
    return (centre.array() >= box.min().array() - voxel).all() &&
           (centre.array() <= box.max().array() + voxel).all();
  }
  // The contact's mean height above the floor (NaN: no voxels).
  float contactHeight(const Contact& c) const {
    double sum = 0.0;
    size_t n = 0;
    for (const auto& side : c.side) {
      for (const auto& v : side) {
        sum += heightOf(v);
        ++n;
      }
    }
    return n == 0 ? std::numeric_limits<float>::quiet_NaN() : float(sum / double(n));
  }
  // Whether the contact lies in the top quarter of `base`'s height above the floor.
  bool atTop(Label base, const Contact& c) const {
    const float top = height.at(base).second;
    return contactHeight(c) >= top - 0.25f * (top - floor_m);
  }
  bool unitStands(Label root, absl::flat_hash_map<Label, Label>& parent) const {
    for (const auto& [l, h] : height) {
      if (h.first <= floor_m + reach_m && findRoot(&parent, l) == root) return true;
    }
    return false;
  }
};

StandingParts standingParts(const RoomStructure& room,
                            const absl::flat_hash_map<Label, std::vector<tsdf::VoxelIndex>>& voxels_of,
                            float voxel) {
  StandingParts s;
  if (!room.up_found) return s;
  const RoomPlane* floor = nullptr;
  for (const RoomPlane& p : room.planes) {
    if (p.kind == StructureKind::kFloor) floor = &p;
  }
  if (floor == nullptr) return s;
  s.known = true;
  s.up = room.up;
  s.voxel = voxel;
  s.floor_m = floor->offset_m * floor->normal.dot(room.up);
  s.reach_m = floor->band_m + 2.0f * voxel;
  inPlaneBasis(s.up, &s.across[0], &s.across[1]);
  for (const auto& [l, list] : voxels_of) {
    float lo = 1e30f, hi = -1e30f;
    Eigen::Vector2f sum = Eigen::Vector2f::Zero();
    Eigen::AlignedBox2f box;
    for (const auto& v : list) {
      const float h = s.heightOf(v);
      lo = std::min(lo, h);
      hi = std::max(hi, h);
      const Eigen::Vector3f p = (v.cast<float>() + Eigen::Vector3f::Constant(0.5f)) * voxel;
      const Eigen::Vector2f q(p.dot(s.across[0]), p.dot(s.across[1]));
      sum += q;
      box.extend(q);
    }
    s.height[l] = {lo, hi};
    s.voxels[l] = list.size();
    s.centre2d[l] = list.empty() ? Eigen::Vector2f::Zero() : Eigen::Vector2f(sum / float(list.size()));
    s.footprint[l] = box;
  }
  return s;
}

// Which labels are room structure (most of their voxels on a bounding face) and which voxels of
// the others are cut from them (on a bounding face), from out->room; returns the labels with the
// cut voxels cleared, or null when nothing is cut.
std::unique_ptr<LabelBlocks> applyRoom(const tsdf::TsdfLayer& layer, const LabelBlocks& labels,
                                       ObjectGroups* out) {
  const int vps = layer.voxelsPerSide();
  absl::flat_hash_map<Label, std::pair<int64_t, int64_t>> on;  // label → (barrier, all)
  for (const auto& [index, block] : labels) {
    for (int i = 0; i < int(block.size()); ++i) {
      const Label l = block[size_t(i)];
      if (l == 0) continue;
      auto& count = on[l];
      ++count.second;
      const tsdf::VoxelIndex v =
          index * vps + Eigen::Vector3i(i % vps, (i / vps) % vps, i / (vps * vps));
      if (out->room.isBarrier(v)) ++count.first;
    }
  }
  for (const auto& [l, count] : on) {
    if (count.first > 0 && 2 * count.first >= count.second) out->structure.insert(l);
  }
  std::unique_ptr<LabelBlocks> cleared;
  for (const auto& [key, unused] : out->room.barrier) {
    const tsdf::VoxelIndex v = unpackGridKey(key);
    const auto it = labels.find(layer.blockOfVoxel(v));
    if (it == labels.end()) continue;
    const Label l = it->second[layer.linearInBlock(v)];
    if (l == 0 || out->structure.contains(l)) continue;
    out->cut.insert(key);
    if (cleared == nullptr) cleared = std::make_unique<LabelBlocks>(labels);
    (*cleared)[it->first][layer.linearInBlock(v)] = 0;
  }
  return cleared;
}

}  // namespace

ObjectGroups groupObjects(const tsdf::TsdfLayer& layer, const LabelBlocks& all_labels,
                          const GsmParams& params, const Eigen::Vector3f& up_hint,
                          const RoomStructure* room) {
  const int vps = layer.voxelsPerSide();
  const float voxel = layer.voxelSize();
  ObjectGroups out;
  out.room = room != nullptr ? *room : findRoomStructure(layer, all_labels, params, up_hint);
  const std::unique_ptr<LabelBlocks> cleared = applyRoom(layer, all_labels, &out);
  const LabelBlocks& labels = cleared != nullptr ? *cleared : all_labels;
  const int r = std::clamp(1 + int(std::floor(params.object_gap_m / voxel + 1e-3f)), 1, vps);
  // The ball of radius r (without its centre): the voxels that touch a voxel.
  std::vector<Eigen::Vector3i> offsets;
  for (int z = -r; z <= r; ++z) {
    for (int y = -r; y <= r; ++y) {
      for (int x = -r; x <= r; ++x) {
        const int d2 = x * x + y * y + z * z;
        if (d2 > 0 && d2 <= r * r) offsets.emplace_back(x, y, z);
      }
    }
  }
  const auto blocks = sortedBlocks(labels);
  // Pass 1: every label's voxels and shape.
  absl::flat_hash_map<Label, Shape> shapes;
  absl::flat_hash_map<Label, std::vector<tsdf::VoxelIndex>> voxels_of;
  for (const auto* entry : blocks) {
    const auto& [index, block] = *entry;
    Label last = 0;
    Shape* s = nullptr;
    std::vector<tsdf::VoxelIndex>* list = nullptr;
    for (int i = 0; i < int(block.size()); ++i) {
      const Label l = block[size_t(i)];
      if (l == 0) continue;
      if (l != last) {
        last = l;
        s = &shapes[l];
        list = &voxels_of[l];
      }
      const tsdf::VoxelIndex v = index * vps + Eigen::Vector3i(i % vps, (i / vps) % vps, i / (vps * vps));
      const Eigen::Vector3d p = v.cast<double>();
      ++s->n;
      s->sum += p;
      s->outer += p * p.transpose();
      list->push_back(v);
    }
  }
  absl::flat_hash_map<Label, Label> parent;
  for (auto& [l, s] : shapes) {
    parent[l] = l;
    deriveShape(voxel, &s);
    if (s.planar) orientNormal(layer, voxels_of[l], &s);
    // A single part larger than furniture can be is room structure whatever its shape (a bent
    // strip of floor, a wall the segmenter kept whole with its skirting).
    if (!out.structure.contains(l) &&
        fullSpan(s, {&voxels_of[l]}, voxel) > params.object_max_extent_m) {
      out.structure.insert(l);
      ++out.giant_labels;
    }
    s.structure = out.structure.contains(l);
  }
  // Pass 2: contacts between labels that are not structure (structure never connects), each
  // side's voxels next to the other label listed once.
  absl::flat_hash_map<uint64_t, Contact> contacts;
  // (label << 32 | structure label) → the label's voxels next to that structure.
  absl::flat_hash_map<uint64_t, int64_t> touches_structure;
  for (const auto* entry : blocks) {
    const auto& [index, block] = *entry;
    // The 27 blocks around this one, so neighbours cost an array read, not a hash lookup.
    std::array<const std::vector<Label>*, 27> around{};
    for (int dz = -1; dz <= 1; ++dz) {
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = labels.find(index + Eigen::Vector3i(dx, dy, dz));
          around[size_t((dx + 1) + 3 * ((dy + 1) + 3 * (dz + 1)))] =
              it == labels.end() ? nullptr : &it->second;
        }
      }
    }
    for (int i = 0; i < int(block.size()); ++i) {
      const Label l = block[size_t(i)];
      if (l == 0 || out.structure.contains(l)) continue;
      const Eigen::Vector3i local(i % vps, (i / vps) % vps, i / (vps * vps));
      std::array<Label, 8> near{};
      size_t n_near = 0;
      for (const Eigen::Vector3i& o : offsets) {
        const Eigen::Vector3i q = local + o;
        const Eigen::Vector3i nb((q.x() + vps) / vps - 1, (q.y() + vps) / vps - 1,
                                 (q.z() + vps) / vps - 1);
        const std::vector<Label>* other =
            around[size_t((nb.x() + 1) + 3 * ((nb.y() + 1) + 3 * (nb.z() + 1)))];
        if (other == nullptr) continue;
        const Eigen::Vector3i ql = q - nb * vps;
        const Label m = (*other)[size_t(ql.x() + vps * (ql.y() + vps * ql.z()))];
        if (m == 0 || m == l || std::find(near.begin(), near.begin() + long(n_near), m) !=
                                    near.begin() + long(n_near)) {
          continue;
        }
        if (n_near < near.size()) near[n_near++] = m;
      }
      const tsdf::VoxelIndex v = index * vps + local;
      for (size_t k = 0; k < n_near; ++k) {
        const Label m = near[k];
        if (out.structure.contains(m)) {
          ++touches_structure[(uint64_t(l) << 32) | m];
          continue;
        }
        Contact& c = contacts[packPair(l, m)];
        ++c.pairs;
        c.side[l < m ? 0 : 1].push_back(v);
      }
    }
  }
  const LabelLookup lookup(labels, layer);
  const float probe = params.object_support_probe_m / voxel;
  // In label order, so the grouping does not depend on hash order.
  std::vector<uint64_t> keys;
  for (const auto& [key, c] : contacts) keys.push_back(key);
  std::sort(keys.begin(), keys.end());
  const auto unite = [&](Label a, Label b) {
    const Label ra = findRoot(&parent, a), rb = findRoot(&parent, b);
    if (ra != rb) parent[std::max(ra, rb)] = std::min(ra, rb);
  };
  std::vector<std::pair<Label, Label>> supported;  // (resting, support), to be decided below
  const StandingParts standing = standingParts(out.room, voxels_of, voxel);
  std::vector<uint64_t> deferred;  // contacts decided once the standing units are known
  // A standing part → (contact pairs, the contact key) of the standing part it is one base
  // with: of its candidates (base_candidates), the one it touches most.
  std::map<Label, std::pair<int64_t, uint64_t>> base_of;
  std::vector<uint64_t> base_candidates;
  for (const uint64_t key : keys) {
    Contact& c = contacts[key];
    const Label a = Label(key >> 32), b = Label(key & 0xffffffffULL);
    ++out.contacts;
    const Shape& sa = shapes[a];
    const Shape& sb = shapes[b];
    if (c.pairs < params.object_min_contact_voxels) continue;
    if (sa.structure || sb.structure) continue;
    if (restsOn(sa, sb, voxels_of[b], c.side[1], b, lookup, layer, probe, voxel)) {
      supported.push_back({a, b});
      continue;
    }
    if (restsOn(sb, sa, voxels_of[a], c.side[0], a, lookup, layer, probe, voxel)) {
      supported.push_back({b, a});
      continue;
    }
    if (standing.known && !standing.carries(a, b, c)) {
      deferred.push_back(key);
      continue;
    }
    if (standing.known && standing.stands(a) && standing.stands(b)) {
      // One base for the smaller part, chosen below.
      const Label child = standing.smaller(a, b);
      auto& best = base_of[child];
      if (c.pairs > best.first) best = {c.pairs, key};
      base_candidates.push_back(key);
      continue;
    }
    unite(a, b);
  }
  for (const uint64_t key : base_candidates) {
    const Label a = Label(key >> 32), b = Label(key & 0xffffffffULL);
    if (base_of.at(standing.smaller(a, b)).second == key) {
      unite(a, b);
    } else {
      deferred.push_back(key);  // kept apart below where both units stand
    }
  }
  // Units that stand on the floor by themselves stay apart where they touch (a chair tucked
  // under a table); a unit that does not stand (a chair's back, a cow's head) joins the one it
  // touches most.
  std::stable_sort(deferred.begin(), deferred.end(), [&](uint64_t x, uint64_t y) {
    return contacts[x].pairs > contacts[y].pairs;
  });
  for (const uint64_t key : deferred) {
    const Label a = Label(key >> 32), b = Label(key & 0xffffffffULL);
    const Label ra = findRoot(&parent, a), rb = findRoot(&parent, b);
    if (ra == rb) continue;
    if (standing.unitStands(ra, parent) && standing.unitStands(rb, parent)) {
      ++out.standing_cuts;
      continue;
    }
    unite(a, b);
  }
  // A cut holds only where what rests is smaller than its support: the object above it, as
  // grouped without the cut, spans at most object_support_max_ratio of the support's extent
  // along both of its axes (a mug, a box, a monitor on a table). A pedestal on its base carries
  // a seat or a table top as wide as the base, and stays part of that object.
  for (const auto& [upper, support] : supported) {
    const Label ru = findRoot(&parent, upper), rs = findRoot(&parent, support);
    if (ru == rs) continue;
    if (standing.known && !standing.under(upper, support) &&
        standing.unitStands(ru, parent) && standing.unitStands(rs, parent)) {
      ++out.standing_cuts;  // each stands on the floor beside the other: nothing rests on it
      continue;
    }
    const Shape& sb = shapes[support];
    std::vector<Label> resting;  // the labels of the resting object
    for (const auto& [l, unused] : shapes) {
      if (findRoot(&parent, l) == ru) resting.push_back(l);
    }
    const PlaneExtent e = extentAlong(sb, resting, voxels_of);
    bool smaller = true;
    for (int axis = 0; axis < 2; ++axis) {
      smaller = smaller && (e.hi[axis] - e.lo[axis] + 1.0f) * voxel <=
                               params.object_support_max_ratio * sb.extent[axis];
    }
    if (smaller) {
      ++out.supports;
    } else {
      unite(upper, support);
    }
  }
  // The objects (roots) standing on something: touching structure, or resting on a support.
  const auto groundedObjects = [&] {
    absl::flat_hash_set<Label> grounded;
    for (const auto& [key, count] : touches_structure) {
      if (count >= params.object_min_contact_voxels) grounded.insert(findRoot(&parent, Label(key >> 32)));
    }
    for (const auto& [upper, support] : supported) {
      if (findRoot(&parent, upper) != findRoot(&parent, support)) {
        grounded.insert(findRoot(&parent, upper));
      }
    }
    // A part standing on the floor grounds its object, its own voxels on the floor cut or not.
    for (const auto& [l, h] : standing.height) {
      if (standing.stands(l) && !out.structure.contains(l)) grounded.insert(findRoot(&parent, l));
    }
    return grounded;
  };
  if (params.object_shadow_gap_m > 0.0f) {
    const absl::flat_hash_set<Label> grounded = groundedObjects();
    const auto floating = [&](Label l) { return !grounded.contains(findRoot(&parent, l)); };
    joinAcrossShadows(shapes, voxels_of, touches_structure, lookup, layer, r,
                      int(std::floor(params.object_shadow_gap_m / voxel + 1e-3f)),
                      params.object_min_contact_voxels, floating, &out, unite);
  }
  for (const auto& [l, s] : shapes) {
    Label root = findRoot(&parent, l);
    out.members[root].push_back(l);
  }
  // An object larger than furniture can be falls back to its parts: the grouping was not sure.
  std::vector<Label> giants;
  for (const auto& [id, members] : out.members) {
    if (members.size() < 2) continue;
    Shape whole;
    std::vector<const std::vector<tsdf::VoxelIndex>*> lists;
    for (const Label l : members) {
      const Shape& part = shapes.at(l);
      whole.n += part.n;
      whole.sum += part.sum;
      whole.outer += part.outer;
      lists.push_back(&voxels_of.at(l));
    }
    deriveShape(voxel, &whole);
    if (fullSpan(whole, lists, voxel) > params.object_max_extent_m) giants.push_back(id);
  }
  for (const Label id : giants) {
    std::vector<Label> members = std::move(out.members.at(id));
    out.members.erase(id);
    for (const Label l : members) {
      parent[l] = l;
      out.members[l] = {l};
    }
    ++out.giant_fallbacks;
  }
  // The id is the smallest label (the roots already are: unions keep the smaller root).
  for (auto& [id, members] : out.members) {
    std::sort(members.begin(), members.end());
    for (const Label l : members) out.object_of[l] = id;
  }
  if (params.object_annex_height_m > 0.0f) {
    // The objects that float as finally grouped (ascending id).
    const absl::flat_hash_set<Label> grounded = groundedObjects();
    std::vector<Label> floating;
    for (const auto& [id, members] : out.members) {
      if (!out.structure.contains(id) && !grounded.contains(id)) floating.push_back(id);
    }
    std::vector<Label> structure(out.structure.begin(), out.structure.end());
    std::sort(structure.begin(), structure.end());
    for (const Label l : structure) {
      annexFrom(l, shapes[l], voxels_of[l], voxels_of, lookup, layer, offsets,
                params.object_annex_height_m / voxel, floating, params.object_min_contact_voxels,
                &out);
    }
  }
  return out;
}

Label ObjectGroups::partAt(const tsdf::VoxelIndex& v, Label label) const {
  if (annexed_part.empty() || !structure.contains(label)) return label;
  const auto it = annexed_part.find(packGridKey(v));
  return it == annexed_part.end() ? label : it->second;
}

}  // namespace objdb::gsm

