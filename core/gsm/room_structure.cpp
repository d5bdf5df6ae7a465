#include "core/gsm/room_structure.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <map>
#include <numeric>

#include "absl/strings/str_format.h"
#include "core/common/grid_key.h"
#include "core/common/plane_spans.h"

namespace objdb::gsm {
namespace {

// A labelled voxel with its surface point and normal.
struct Surfel {
  tsdf::VoxelIndex v;
  Eigen::Vector3f p;  // the surface point: voxel centre less its TSDF distance along n (world)
  Eigen::Vector3f n;  // unit, towards the observed side (the TSDF grows there)
};

// The TSDF gradient at voxel `local` of `block` (global index `v`) by central differences
// (one-sided where a neighbour is unobserved). Neighbours inside the block are read directly.
bool gradientAt(const tsdf::TsdfLayer& layer, const tsdf::TsdfBlock& block,
                const Eigen::Vector3i& local, const tsdf::VoxelIndex& v, Eigen::Vector3f* g) {
  const int vps = layer.voxelsPerSide();
  const size_t linear = size_t(local.x() + vps * (local.y() + vps * local.z()));
  const tsdf::TsdfVoxel& centre = block.voxel(linear);
  const bool centre_ok = centre.weight > 0.0f;
  const size_t stride[3] = {1, size_t(vps), size_t(vps * vps)};
  for (int a = 0; a < 3; ++a) {
    const tsdf::VoxelIndex e = tsdf::VoxelIndex::Unit(a);
    const tsdf::TsdfVoxel* plus =
        local(a) + 1 < vps ? &block.voxel(linear + stride[a]) : layer.voxel(v + e);
    const tsdf::TsdfVoxel* minus =
        local(a) > 0 ? &block.voxel(linear - stride[a]) : layer.voxel(v - e);
    const bool p = plus != nullptr && plus->weight > 0.0f;
    const bool m = minus != nullptr && minus->weight > 0.0f;
    if (p && m) {
      (*g)(a) = 0.5f * (plus->distance - minus->distance);
    } else if (p && centre_ok) {
      (*g)(a) = plus->distance - centre.distance;
    } else if (m && centre_ok) {
      (*g)(a) = centre.distance - minus->distance;
    } else {
      return false;
    }
  }
  return g->squaredNorm() > 1e-12f;
}

std::vector<Surfel> collectSurfels(const tsdf::TsdfLayer& layer, const LabelBlocks& labels) {
  const auto blocks = sortedBlocks(labels);
  const int vps = layer.voxelsPerSide();
  std::vector<Surfel> out;
  for (const auto* entry : blocks) {
    const auto& [index, block] = *entry;
    const tsdf::TsdfBlock* tsdf_block = layer.block(index);
    if (tsdf_block == nullptr) continue;
    for (int i = 0; i < int(block.size()); ++i) {
      if (block[size_t(i)] == 0) continue;
      const Eigen::Vector3i local(i % vps, (i / vps) % vps, i / (vps * vps));
      const tsdf::VoxelIndex v = index * vps + local;
      const tsdf::TsdfVoxel& c = tsdf_block->voxel(size_t(i));
      const bool centre_ok = c.weight > 0.0f;
      Eigen::Vector3f g;
      if (!gradientAt(layer, *tsdf_block, local, v, &g)) continue;
      const Eigen::Vector3f n = g.normalized();
      const float d = centre_ok ? std::clamp(c.distance, -layer.voxelSize(), layer.voxelSize())
                                : 0.0f;
      out.push_back({v, layer.voxelCenter(v) - d * n, n});
    }
  }
  return out;
}

// Dominant normal directions (see the header), each with the surfels closest to it.
std::vector<Eigen::Vector3f> dominantDirections(const std::vector<Surfel>& surfels, float cos_tol,
                                                size_t min_support) {
  std::vector<Eigen::Vector3f> dirs;
  // Seeds and counts on a fixed subsample (deterministic), refinement on every surfel.
  const size_t stride = std::max<size_t>(1, surfels.size() / 4000);
  std::vector<Eigen::Vector3f> sample;
  for (size_t i = 0; i < surfels.size(); i += stride) sample.push_back(surfels[i].n);
  const float cos_half = std::cos(0.5f * std::acos(cos_tol));
  std::vector<bool> used(sample.size(), false);
  while (int(dirs.size()) < kMaxDirections) {
    size_t best = 0, best_count = 0;
    const size_t seed_stride = std::max<size_t>(1, sample.size() / 500);
    for (size_t s = 0; s < sample.size(); s += seed_stride) {
      if (used[s]) continue;
      size_t count = 0;
      for (size_t t = 0; t < sample.size(); ++t) {
        count += (!used[t] && sample[s].dot(sample[t]) >= cos_half) ? 1 : 0;
      }
      if (count > best_count) {
        best_count = count;
        best = s;
      }
    }
    if (best_count * stride < min_support) break;
    Eigen::Vector3f d = sample[best];
    for (int iteration = 0; iteration < 3; ++iteration) {
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      for (const Surfel& s : surfels) {
        if (s.n.dot(d) >= cos_tol) sum += s.n;
      }
      if (sum.squaredNorm() < 1e-12f) break;
      d = sum.normalized();
    }
    dirs.push_back(d);
    for (size_t t = 0; t < sample.size(); ++t) {
      if (sample[t].dot(d) >= cos_tol) used[t] = true;
    }
  }
  return dirs;
}

float median(std::vector<float> values) {
  if (values.empty()) return 0.0f;
  const auto mid = values.begin() + long(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

// A plane in the making: one direction's surfels within a band of an offset.
struct Candidate {
  int direction = 0;
  float centre = 0.0f, band = 0.0f;
  float lo = 0.0f, hi = 0.0f;  // the band's ends (a joined plane covers both sheets)
  int sheets = 1;
  std::vector<uint32_t> members;  // surfel indices
};

// The planes of one direction: histogram peaks of the offsets (see the header).
std::vector<Candidate> planesOf(int direction, const Eigen::Vector3f& d,
                                const std::vector<Surfel>& surfels,
                                const std::vector<uint32_t>& members, float voxel,
                                size_t min_voxels, float sigmas) {
  std::vector<Candidate> out;
  if (members.empty()) return out;
  std::vector<float> offset(members.size());
  float lo = 1e30f, hi = -1e30f;
  for (size_t i = 0; i < members.size(); ++i) {
    offset[i] = d.dot(surfels[members[i]].p);
    lo = std::min(lo, offset[i]);
    hi = std::max(hi, offset[i]);
  }
  const float bin = 0.5f * voxel;
  const size_t bins = size_t((hi - lo) / bin) + 1;
  std::vector<int> count(bins, 0);
  const auto binOf = [&](float o) { return std::min(bins - 1, size_t((o - lo) / bin)); };
  for (const float o : offset) ++count[binOf(o)];
  std::vector<bool> taken(members.size(), false);
  while (int(out.size()) < kMaxPlanes) {
    // The densest window of three bins (1.5 voxels).
    size_t peak = 0;
    int peak_count = -1;
    for (size_t b = 0; b < bins; ++b) {
      const int c = count[b] + (b > 0 ? count[b - 1] : 0) + (b + 1 < bins ? count[b + 1] : 0);
      if (c > peak_count) {
        peak_count = c;
        peak = b;
      }
    }
    if (size_t(std::max(peak_count, 0)) < min_voxels) break;
    // Centre and band from the plane's own spread: median and `sigmas` robust σ (MAD), at least
    // a voxel;
    // twice, the window following the band.
    float centre = lo + (float(peak) + 0.5f) * bin;
    float band = 2.0f * voxel;
    for (int iteration = 0; iteration < 3; ++iteration) {
      std::vector<float> near;
      for (size_t i = 0; i < members.size(); ++i) {
        if (!taken[i] && std::abs(offset[i] - centre) <= band) near.push_back(offset[i]);
      }
      if (near.empty()) break;
      centre = median(near);
      for (float& o : near) o = std::abs(o - centre);
      band = std::max(voxel, sigmas * 1.4826f * median(near));
    }
    Candidate c;
    c.direction = direction;
    c.centre = centre;
    c.band = band;
    c.lo = centre - band;
    c.hi = centre + band;
    for (size_t i = 0; i < members.size(); ++i) {
      if (taken[i] || std::abs(offset[i] - centre) > band) continue;
      taken[i] = true;
      --count[binOf(offset[i])];
      c.members.push_back(members[i]);
    }
    // The peak's own bins are spent even if the band missed them (no endless loop).
    for (size_t b = peak > 0 ? peak - 1 : 0; b <= std::min(bins - 1, peak + 1); ++b) {
      if (count[b] > 0 && c.members.empty()) count[b] = 0;
    }
    if (c.members.size() >= min_voxels) out.push_back(std::move(c));
  }
  return out;
}

// Joins parallel planes of one direction whose bands touch (within a voxel): two sheets of one
// wall seen from drifted poses, a rug on the floor, coplanar pieces of one counter. Faces are
// found after this, so two table tops at one height stay two faces.
void joinSheets(std::vector<Candidate>* planes, float voxel) {
  std::sort(planes->begin(), planes->end(), [](const Candidate& x, const Candidate& y) {
    return std::tie(x.direction, x.centre) < std::tie(y.direction, y.centre);
  });
  std::vector<Candidate> out;
  for (Candidate& c : *planes) {
    if (!out.empty() && out.back().direction == c.direction && c.lo - out.back().hi <= voxel) {
      Candidate& prev = out.back();
      prev.members.insert(prev.members.end(), c.members.begin(), c.members.end());
      prev.lo = std::min(prev.lo, c.lo);
      prev.hi = std::max(prev.hi, c.hi);
      prev.centre = 0.5f * (prev.lo + prev.hi);
      prev.band = 0.5f * (prev.hi - prev.lo);
      prev.sheets += c.sheets;
      continue;
    }
    out.push_back(std::move(c));
  }
  *planes = std::move(out);
}

// A connected face of a plane.
struct Face {
  std::vector<uint32_t> members;  // surfel indices
  float span[2] = {0.0f, 0.0f};
  size_t behind = 0;
  size_t interior_voxels = 0;
};

// A plane's voxels on a dense grid of in-plane cells (a voxel wide, coarser for a huge plane),
// split into faces.
struct PlaneFaces {
  Eigen::Vector3f a, b;  // in-plane basis
  float cell = 0.0f;
  int i0 = 0, j0 = 0, w = 0, h = 0;
  std::vector<int32_t> face;     // per cell: its face (−1: none)
  std::vector<uint8_t> interior; // per cell: well inside its face (the behind test's footprint)
  std::vector<Face> faces;
  // The cell of a point (−1: outside the grid).
  // The grid column and row of a point (may lie outside the grid).
  Eigen::Vector2i cellIndex(const Eigen::Vector3f& p) const {
    return {int(std::floor(p.dot(a) / cell)) - i0, int(std::floor(p.dot(b) / cell)) - j0};
  }
  // The cell at column i, row j (−1: outside the grid).
  long cellAt(int i, int j) const {
    return (i < 0 || j < 0 || i >= w || j >= h) ? -1 : long(j) * w + i;
  }
  long cellOf(const Eigen::Vector3f& p) const {
    const Eigen::Vector2i c = cellIndex(p);
    return cellAt(c.x(), c.y());
  }
};

constexpr long kMaxGridCells = 1L << 22;

PlaneFaces facesOf(const Candidate& plane, const Eigen::Vector3f& n,
                   const std::vector<Surfel>& surfels, float voxel) {
  PlaneFaces out;
  inPlaneBasis(n, &out.a, &out.b);
  float lo[2] = {1e30f, 1e30f}, hi[2] = {-1e30f, -1e30f};
  for (const uint32_t m : plane.members) {
    const float u = surfels[m].p.dot(out.a), v = surfels[m].p.dot(out.b);
    lo[0] = std::min(lo[0], u);
    hi[0] = std::max(hi[0], u);
    lo[1] = std::min(lo[1], v);
    hi[1] = std::max(hi[1], v);
  }
  out.cell = voxel;
  const double area = double(hi[0] - lo[0] + voxel) * double(hi[1] - lo[1] + voxel);
  if (area / double(voxel * voxel) > double(kMaxGridCells)) {
    out.cell = float(std::sqrt(area / double(kMaxGridCells))) * 1.01f;
  }
  out.i0 = int(std::floor(lo[0] / out.cell));
  out.j0 = int(std::floor(lo[1] / out.cell));
  out.w = int(std::floor(hi[0] / out.cell)) - out.i0 + 1;
  out.h = int(std::floor(hi[1] / out.cell)) - out.j0 + 1;
  const size_t cells = size_t(out.w) * size_t(out.h);
  std::vector<uint32_t> count(cells + 1, 0);  // members per cell, then offsets
  std::vector<long> cell_of(plane.members.size());
  for (size_t k = 0; k < plane.members.size(); ++k) {
    cell_of[k] = out.cellOf(surfels[plane.members[k]].p);
    ++count[size_t(cell_of[k]) + 1];
  }
  for (size_t c = 0; c < cells; ++c) count[c + 1] += count[c];
  std::vector<uint32_t> by_cell(plane.members.size());
  {
    std::vector<uint32_t> next(count.begin(), count.end() - 1);
    for (size_t k = 0; k < plane.members.size(); ++k) {
      by_cell[next[size_t(cell_of[k])]++] = plane.members[k];
    }
  }
  out.face.assign(cells, -1);
  std::vector<long> stack;
  std::vector<std::vector<long>> face_cells;
  for (long start = 0; start < long(cells); ++start) {
    if (count[size_t(start) + 1] == count[size_t(start)] || out.face[size_t(start)] >= 0) continue;
    const int id = int(face_cells.size());
    face_cells.emplace_back();
    out.face[size_t(start)] = id;
    stack.assign(1, start);
    while (!stack.empty()) {
      const long c = stack.back();
      stack.pop_back();
      face_cells.back().push_back(c);
      const int ci = int(c % out.w), cj = int(c / out.w);
      for (int dj = -2; dj <= 2; ++dj) {  // across one-cell holes (sensor dropouts)
        for (int di = -2; di <= 2; ++di) {
          const long q = out.cellAt(ci + di, cj + dj);
          if (q < 0) continue;
          if (count[size_t(q) + 1] == count[size_t(q)] || out.face[size_t(q)] >= 0) continue;
          out.face[size_t(q)] = id;
          stack.push_back(q);
        }
      }
    }
  }
  out.interior.assign(cells, 0);
  out.faces.resize(face_cells.size());
  for (size_t f = 0; f < face_cells.size(); ++f) {
    Face& face = out.faces[f];
    std::sort(face_cells[f].begin(), face_cells[f].end());
    for (const long c : face_cells[f]) {
      face.members.insert(face.members.end(), by_cell.begin() + count[size_t(c)],
                          by_cell.begin() + count[size_t(c) + 1]);
      // Interior: at least 20 of the 25 cells around it are the face's (its rim, where a
      // cabinet front meets a counter top or a floor meets a wall, is not).
      const int ci = int(c % out.w), cj = int(c / out.w);
      int around = 0;
      for (int dj = -2; dj <= 2; ++dj) {
        for (int di = -2; di <= 2; ++di) {
          const long q = out.cellAt(ci + di, cj + dj);
          around += (q >= 0 && out.face[size_t(q)] == int(f)) ? 1 : 0;
        }
      }
      if (around >= 20) {
        out.interior[size_t(c)] = 1;
        face.interior_voxels += count[size_t(c) + 1] - count[size_t(c)];
      }
    }
    planeSpans(
        face.members.size(), [&](size_t i) { return surfels[face.members[i]].p; }, n, face.span);
  }
  return out;
}

}  // namespace

std::vector<const LabelBlocks::value_type*> sortedBlocks(const LabelBlocks& labels) {
  std::vector<const LabelBlocks::value_type*> blocks;
  blocks.reserve(labels.size());
  for (const auto& entry : labels) blocks.push_back(&entry);
  std::sort(blocks.begin(), blocks.end(), [](const auto* a, const auto* b) {
    return std::tie(a->first.z(), a->first.y(), a->first.x()) <
           std::tie(b->first.z(), b->first.y(), b->first.x());
  });
  return blocks;
}

const char* structureKindName(StructureKind kind) {
  switch (kind) {
    case StructureKind::kNone: return "none";
    case StructureKind::kFloor: return "floor";
    case StructureKind::kCeiling: return "ceiling";
    case StructureKind::kWall: return "wall";
    case StructureKind::kSupport: return "support";
    case StructureKind::kVerticalFace: return "vertical face";
    case StructureKind::kBoundary: return "boundary";
  }
  return "?";
}

bool RoomStructure::isBarrier(const tsdf::VoxelIndex& v) const {
  return barrier.contains(packGridKey(v));
}

size_t RoomStructure::structurePlanes() const {
  size_t n = 0;
  for (const RoomPlane& p : planes) n += p.kind != StructureKind::kNone ? 1 : 0;
  return n;
}

std::string RoomStructure::summary() const {
  std::map<std::string, int> kinds;
  for (const RoomPlane& p : planes) {
    if (p.kind != StructureKind::kNone) ++kinds[structureKindName(p.kind)];
  }
  std::string names;
  for (const auto& [name, n] : kinds) {
    absl::StrAppend(&names, names.empty() ? "" : ", ", n, " ", name);
  }
  return absl::StrFormat(
      "%s; %d structure planes of %d (%s); %.0f %% of %d surface voxels; %.1f ms",
      up_found ? absl::StrFormat("up (%.2f %.2f %.2f)", up.x(), up.y(), up.z())
               : std::string("no up direction"),
      structurePlanes(), planes.size(), names.empty() ? "none" : names,
      surface_voxels == 0 ? 0.0 : 100.0 * double(barrier.size()) / double(surface_voxels),
      surface_voxels, ms);
}

RoomStructure findRoomStructure(const tsdf::TsdfLayer& layer, const LabelBlocks& labels,
                                const GsmParams& params, const Eigen::Vector3f& up_hint) {
  const auto start = std::chrono::steady_clock::now();
  RoomStructure out;
  const float voxel = layer.voxelSize();
  const std::vector<Surfel> surfels = collectSurfels(layer, labels);
  out.surface_voxels = surfels.size();
  const float cos_tol = std::cos(params.structure_normal_deg * float(M_PI) / 180.0f);
  // The smallest bounding face's area in voxels, half of it (holes): fewer cannot be one.
  const size_t min_voxels = std::max<size_t>(
      50, size_t(0.5f * params.object_structure_extent_m * params.structure_min_span_m /
                 (voxel * voxel)));
  const std::vector<Eigen::Vector3f> dirs = dominantDirections(surfels, cos_tol, min_voxels);
  // Each surfel to its closest direction within the tolerance.
  std::vector<std::vector<uint32_t>> of_dir(dirs.size());
  for (size_t i = 0; i < surfels.size(); ++i) {
    int best = -1;
    float best_dot = cos_tol;
    for (size_t k = 0; k < dirs.size(); ++k) {
      const float c = surfels[i].n.dot(dirs[k]);
      if (c >= best_dot) {
        best_dot = c;
        best = int(k);
      }
    }
    if (best >= 0) of_dir[size_t(best)].push_back(uint32_t(i));
  }
  std::vector<Candidate> candidates;
  for (size_t k = 0; k < dirs.size(); ++k) {
    for (Candidate& c : planesOf(int(k), dirs[k], surfels, of_dir[k], voxel, min_voxels,
                                     params.structure_band_sigmas)) {
      candidates.push_back(std::move(c));
    }
  }
  joinSheets(&candidates, voxel);
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& x, const Candidate& y) {
    return x.members.size() != y.members.size() ? x.members.size() > y.members.size()
                                                : std::tie(x.direction, x.centre) <
                                                      std::tie(y.direction, y.centre);
  });
  if (candidates.size() > size_t(kMaxPlanes)) candidates.resize(size_t(kMaxPlanes));

  // Up: the direction closest to the cameras' image up, when it is within the tolerance.
  if (up_hint.squaredNorm() > 0.25f) {
    const Eigen::Vector3f hint = up_hint.normalized();
    float best = cos_tol;
    for (const Eigen::Vector3f& d : dirs) {
      if (d.dot(hint) >= best) {
        best = d.dot(hint);
        out.up = d;
        out.up_found = true;
      }
    }
  }

  // Faces, the behind test, and the barrier.
  struct Bounding {
    size_t plane;
    const Face* face;
  };
  std::vector<PlaneFaces> faces(candidates.size());
  std::vector<size_t> behind_plane(candidates.size(), 0);  // surfels behind the whole plane
  std::vector<Bounding> bounding;
  const auto bigEnough = [&](const Face& face) {
    return face.span[1] >= params.object_structure_extent_m &&
           face.span[0] >= params.structure_min_span_m && face.interior_voxels > 0;
  };
  for (size_t p = 0; p < candidates.size(); ++p) {
    const Candidate& c = candidates[p];
    const Eigen::Vector3f n = dirs[size_t(c.direction)];
    faces[p] = facesOf(c, n, surfels, voxel);
    // The behind test only for faces big enough to bound the room.
    if (std::none_of(faces[p].faces.begin(), faces[p].faces.end(), bigEnough)) continue;
    const float behind_at = c.lo - 2.0f * voxel;  // behind the band by more than two voxels
    for (const Surfel& s : surfels) {
      if (n.dot(s.p) >= behind_at) continue;
      ++behind_plane[p];
      const long cell = faces[p].cellOf(s.p);
      if (cell < 0 || !faces[p].interior[size_t(cell)]) continue;
      ++faces[p].faces[size_t(faces[p].face[size_t(cell)])].behind;
    }
    for (const Face& face : faces[p].faces) {
      if (bigEnough(face) &&
          float(face.behind) <= params.structure_max_behind_share * float(face.interior_voxels)) {
        bounding.push_back({p, &face});
      }
    }
  }
  // The floor's height along up: the lowest bounding face facing up.
  float floor_height = 1e30f;
  const float sin_tol = std::sqrt(std::max(0.0f, 1.0f - cos_tol * cos_tol));
  if (out.up_found) {
    for (const Bounding& b : bounding) {
      const Candidate& c = candidates[b.plane];
      if (dirs[size_t(c.direction)].dot(out.up) >= cos_tol) {
        floor_height = std::min(floor_height, c.centre * dirs[size_t(c.direction)].dot(out.up));
      }
    }
  }
  out.planes.resize(candidates.size());
  for (size_t p = 0; p < candidates.size(); ++p) {
    const Candidate& c = candidates[p];
    RoomPlane& plane = out.planes[p];
    plane.normal = dirs[size_t(c.direction)];
    plane.offset_m = c.centre;
    plane.band_m = c.band;
    plane.sheets = c.sheets;
    plane.voxels = c.members.size();
    for (const Face& f : faces[p].faces) {
      if (f.members.size() > 0 && f.span[1] * f.span[0] >= plane.span_m[1] * plane.span_m[0]) {
        plane.span_m[0] = f.span[0];
        plane.span_m[1] = f.span[1];
      }
    }
  }
  std::vector<size_t> face_size(candidates.size(), 0);  // its largest bounding face's voxels
  std::vector<std::vector<uint8_t>> is_bounding(candidates.size());
  for (size_t p = 0; p < candidates.size(); ++p) is_bounding[p].assign(faces[p].faces.size(), 0);
  for (const Bounding& b : bounding) {
    const Candidate& c = candidates[b.plane];
    RoomPlane& plane = out.planes[b.plane];
    StructureKind kind = StructureKind::kBoundary;
    if (out.up_found) {
      const float along = plane.normal.dot(out.up);
      if (along >= cos_tol) {
        const float height = c.centre * along;
        kind = height <= floor_height + c.band + voxel ? StructureKind::kFloor
                                                       : StructureKind::kSupport;
      } else if (along <= -cos_tol) {
        kind = StructureKind::kCeiling;
      } else if (std::abs(along) <= sin_tol) {
        // A wall has the whole map in front of it; behind a cabinet front stands the wall above
        // the counter, behind a partition the other side of the room.
        const bool wall = float(behind_plane[b.plane]) <=
                          params.structure_max_behind_share * float(surfels.size());
        kind = wall ? StructureKind::kWall : StructureKind::kVerticalFace;
      }
    }
    // The plane is named after its largest bounding face.
    if (face_size[b.plane] < b.face->members.size()) {
      plane.kind = kind;
      face_size[b.plane] = b.face->members.size();
    }
    is_bounding[b.plane][size_t(b.face - faces[b.plane].faces.data())] = 1;
  }
  // The barrier: every surface voxel within a bounding face's band over its cells or next to
  // them, whatever its normal (where a floor meets a wall, the normals turn between the two).
  for (size_t p = 0; p < candidates.size(); ++p) {
    if (face_size[p] == 0) continue;
    const Candidate& c = candidates[p];
    const Eigen::Vector3f n = dirs[size_t(c.direction)];
    const PlaneFaces& grid = faces[p];
    const auto bounding = [&](int i, int j) {
      const long cell = grid.cellAt(i, j);
      if (cell < 0) return false;
      const int32_t f = grid.face[size_t(cell)];
      return f >= 0 && is_bounding[p][size_t(f)] != 0;
    };
    for (const Surfel& s : surfels) {
      const float o = n.dot(s.p);
      if (o < c.lo || o > c.hi) continue;
      const Eigen::Vector2i ij = grid.cellIndex(s.p);
      const int i = ij.x(), j = ij.y();
      if (!bounding(i, j) && !bounding(i - 1, j) && !bounding(i + 1, j) && !bounding(i, j - 1) &&
          !bounding(i, j + 1)) {
        continue;
      }
      if (out.barrier.emplace(packGridKey(s.v), int(p)).second) ++out.planes[p].barrier_voxels;
    }
  }
  out.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
               .count();
  return out;
}

}  // namespace objdb::gsm
