#include "client/db_score.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>

#include "absl/container/flat_hash_map.h"
#include "absl/container/flat_hash_set.h"
#include "absl/strings/str_format.h"
#include "core/common/grid_key.h"
#include "core/common/plane_spans.h"
#include "core/model/features.h"

namespace objdb::cli {

StatusOr<GroundTruth> readGroundTruth(const std::map<std::string, std::string>& datasets,
                                      const std::set<int>& structure_ids) {
  GroundTruth objects;
  for (const auto& [session, folder] : datasets) {
    OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<io::Dataset> ds, io::openDataset(folder));
    if (!ds->hasInstances()) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "dataset %s has no ground truth (no instances/ folder); `objdb report merges` draws "
          "its merges",
          folder));
    }
    const std::filesystem::path json = std::filesystem::path(folder) / "objects.json";
    std::error_code ec;
    if (std::filesystem::exists(json, ec)) {
      OBJDB_ASSIGN_OR_RETURN(std::vector<io::GroundTruthObject> read, io::readObjectsJson(json));
      for (auto& g : read) objects[session][g.id] = g;
      continue;
    }
    // Class labels without objects.json (label-fusion's labels/): every id is one object of kind
    // "label <id>"; those of structure_ids are structure.
    std::set<int> ids;
    for (size_t f = 0; f < ds->size(); ++f) {
      OBJDB_ASSIGN_OR_RETURN(const Frame frame, ds->loadFrame(f));
      if (!frame.instances) continue;
      for (const uint16_t id : frame.instances->data) {
        if (id != 0) ids.insert(int(id));
      }
    }
    std::fprintf(stderr, "session %s: no objects.json; its %zu ids are one object of kind \"label "
                         "<id>\" each\n",
                 session.c_str(), ids.size());
    for (const int id : ids) {
      io::GroundTruthObject g;
      g.id = id;
      g.category = absl::StrFormat("label %d", id);
      g.is_structure = structure_ids.count(id) != 0;
      objects[session][id] = g;
    }
  }
  return objects;
}

namespace {

// The true object of instance `id` in `session` (null: background or unknown).
const io::GroundTruthObject* trueObject(const GroundTruth& truth, const std::string& session,
                                        int id) {
  const auto s = truth.find(session);
  if (s == truth.end() || id == 0) return nullptr;
  const auto o = s->second.find(id);
  return o == s->second.end() ? nullptr : &o->second;
}

// TruthScore's purity, leakage and excess extent (see db_score.h).
void scorePurity(const std::vector<Row>& rows, const GroundTruth& truth, TruthScore* s) {
  constexpr double kImpurePlacement = 0.8, kImpureModel = 0.95;
  constexpr double kExcess = 0.05;  // m: "within a few cm of its true object's"
  constexpr size_t kMinOnObject = 10;  // points, for a span
  double placement_sum = 0.0, model_sum = 0.0, excess_sum = 0.0;
  size_t object_votes = 0, structure_votes = 0;
  std::vector<std::pair<double, std::string>> junk, impure;
  s->model_purity_min = 1.0;
  for (const Row& row : rows) {
    if (row.summary.structure) continue;
    // The model's kind: the true object kind most of its points fell on, pooled over placements.
    std::map<std::string, size_t> by_kind, everything;  // object kinds; all, structure too
    size_t total = 0, on_structure = 0;
    for (const Placement& p : row.placements) {
      for (const auto& [id, n] : p.votes) {
        total += n;
        const io::GroundTruthObject* g = trueObject(truth, p.session, id);
        everything[g == nullptr ? std::string("nothing") : g->category] += n;
        if (g == nullptr) continue;
        if (g->is_structure) {
          on_structure += n;
        } else {
          by_kind[g->category] += n;
        }
      }
    }
    if (by_kind.empty() || total == 0) continue;
    const auto best = std::max_element(by_kind.begin(), by_kind.end(), [](const auto& a,
                                                                          const auto& b) {
      return a.second < b.second;
    });
    if (best->second < on_structure) continue;  // mostly floor or wall: scored as structure
    const std::string& kind = best->first;
    const double purity = double(best->second) / double(total);
    ++s->pure_models;
    model_sum += purity;
    s->model_purity_min = std::min(s->model_purity_min, purity);
    if (purity < kImpureModel) {
      ++s->impure_models;
      // What else it holds, most first.
      std::vector<std::pair<size_t, std::string>> others;
      for (const auto& [k, n] : everything) {
        if (k != kind) others.emplace_back(n, k);
      }
      std::sort(others.rbegin(), others.rend());
      std::string holds;
      for (size_t i = 0; i < others.size() && i < 3; ++i) {
        holds += absl::StrFormat("%s%s %.0f %%", i ? ", " : "", others[i].second,
                                 100.0 * double(others[i].first) / double(total));
      }
      impure.emplace_back(purity, absl::StrFormat("model %d (%s, %d placement(s)): purity %.0f %%; "
                                                  "also %s",
                                                  row.summary.id, kind, row.placements.size(),
                                                  100.0 * purity, holds));
    }
    object_votes += total;
    structure_votes += on_structure;
    for (const Placement& p : row.placements) {
      double share = 0.0;
      const int id = truthOf(p, &share);
      const io::GroundTruthObject* g = trueObject(truth, p.session, id);
      if (g == nullptr || g->is_structure || share <= 0.0) continue;
      ++s->pure_placements;
      placement_sum += share;
      s->impure_placements += share < kImpurePlacement ? 1 : 0;
    }
    // Its points on its kind in any placement, against all of them.
    std::vector<Eigen::Vector3f> on_object;
    for (size_t i = 0; i < row.points.size(); ++i) {
      for (const Placement& p : row.placements) {
        if (i >= p.point_votes.size() || !p.point_votes[i].voted) continue;
        const io::GroundTruthObject* g =
            trueObject(truth, p.session, p.point_votes[i].instance);
        if (g != nullptr && !g->is_structure && g->category == kind) {
          on_object.push_back(row.points[i]);
          break;
        }
      }
    }
    if (on_object.size() < kMinOnObject) continue;
    const double all = principalSpans(row.points)(0), own = principalSpans(on_object)(0);
    const double excess = std::max(0.0, all - own);
    ++s->extent_models;
    excess_sum += excess;
    s->extent_excess_max = std::max(s->extent_excess_max, excess);
    s->extent_over += excess > kExcess ? 1 : 0;
    junk.emplace_back(excess, absl::StrFormat(
                                  "model %d (%s, %d placement(s)): %.2f m across, its %s points "
                                  "%.2f m; purity %.0f %%",
                                  row.summary.id, kind, row.placements.size(), all, kind, own,
                                  100.0 * purity));
  }
  s->placement_purity = s->pure_placements ? placement_sum / double(s->pure_placements) : 0.0;
  s->model_purity = s->pure_models ? model_sum / double(s->pure_models) : 0.0;
  if (s->pure_models == 0) s->model_purity_min = 0.0;
  s->extent_excess = s->extent_models ? excess_sum / double(s->extent_models) : 0.0;
  s->leakage = object_votes ? double(structure_votes) / double(object_votes) : 0.0;
  std::sort(junk.begin(), junk.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  for (size_t i = 0; i < junk.size() && i < 5; ++i) {
    if (junk[i].first > kExcess) s->junk.push_back(junk[i].second);
  }
  std::sort(impure.begin(), impure.end());
  for (size_t i = 0; i < impure.size() && i < 5; ++i) s->impure.push_back(impure[i].second);
}

}  // namespace

TruthScore scoreTruth(const std::vector<Row>& rows, const GroundTruth& truth) {
  TruthScore s;
  // Kind of every placement ("" unknown) and whether it is true structure.
  struct Truth {
    std::string kind;
    std::string object;  // session/id
    bool structure = false;
  };
  std::vector<std::vector<Truth>> truths(rows.size());
  std::map<std::string, size_t> mergeable_per_kind;
  s.models = rows.size();
  for (size_t r = 0; r < rows.size(); ++r) {
    const Row& row = rows[r];
    const bool unmatched = row.summary.planar || row.summary.structure;
    for (const Placement& p : row.placements) {
      ++s.placements;
      double purity = 0.0;
      const int id = truthOf(p, &purity);
      Truth t;
      if (const io::GroundTruthObject* g = trueObject(truth, p.session, id)) {
        t.kind = g->category;
        t.structure = g->is_structure;
        t.object = absl::StrFormat("%s/%d", p.session, id);
        ++s.known;
      }
      s.planar += row.summary.planar ? 1 : 0;
      s.structure += row.summary.structure ? 1 : 0;
      if (t.structure) {
        ++s.on_structure;
        s.on_structure_flagged += row.summary.structure ? 1 : 0;
      }
      if (!unmatched) {
        ++s.mergeable;
        if (!t.kind.empty() && !t.structure) ++mergeable_per_kind[t.kind];
      }
      truths[r].push_back(t);
    }
    if (row.placements.size() < 2) continue;
    ++s.multi;
    s.multi_place += places(row) >= 2 ? 1 : 0;
    std::set<std::string> kinds;
    bool has_structure = false;
    for (const Truth& t : truths[r]) {
      if (!t.kind.empty()) kinds.insert(t.kind);
      has_structure = has_structure || t.structure;
    }
    if (kinds.size() > 1) {
      ++s.erroneous;
      std::string list;
      for (const auto& k : kinds) list += (list.empty() ? "" : " + ") + k;
      s.findings.push_back(
          absl::StrFormat("erroneous merge: object %d holds %s", row.summary.id, list));
    }
    if (has_structure) {
      ++s.structure_merges;
      s.findings.push_back(absl::StrFormat(
          "structure merge: object %d holds a floor or wall placement", row.summary.id));
    }
  }
  // Recall: mergeable placements of kinds with two or more of them that share their model with
  // another placement of their kind at another place.
  std::map<std::string, std::set<int64_t>> models_of_object;
  std::map<std::string, std::set<std::string>> objects_of_kind;
  std::map<std::string, std::set<int64_t>> models_of_kind;
  for (size_t r = 0; r < rows.size(); ++r) {
    const Row& row = rows[r];
    if (row.summary.planar || row.summary.structure) continue;
    for (size_t a = 0; a < truths[r].size(); ++a) {
      const Truth& t = truths[r][a];
      if (t.kind.empty() || t.structure) continue;
      models_of_object[t.object].insert(row.summary.id);
      objects_of_kind[t.kind].insert(t.object);
      models_of_kind[t.kind].insert(row.summary.id);
      if (mergeable_per_kind[t.kind] < 2) continue;
      ++s.repeated;
      // Another placement of its kind elsewhere: one surface under two GSM labels at one place
      // (the same object re-segmented) is not a repeated object found.
      for (size_t b = 0; b < truths[r].size(); ++b) {
        if (b == a || truths[r][b].kind != t.kind) continue;
        if (samePlace(row, row.placements[a], row.placements[b])) continue;
        ++s.with_kind;
        break;
      }
    }
  }
  scorePurity(rows, truth, &s);
  // Ids are per session: an object seen in three sessions counts three times.
  for (const auto& [kind, ids] : objects_of_kind) {
    size_t models = 0;
    for (const auto& id : ids) models += models_of_object[id].size();
    s.kinds.push_back({kind, ids.size(), mergeable_per_kind[kind],
                       double(models) / double(ids.size()), models_of_kind[kind].size()});
  }
  return s;
}

namespace {
void line(const char* what, const std::string& value) {
  std::printf("%-58s %s\n", what, value.c_str());
}
}  // namespace

void printTruthScore(const TruthScore& s) {
  for (const auto& f : s.findings) std::printf("%s\n", f.c_str());
  line("placements (raw segments in the database)", std::to_string(s.placements));
  line("  with ground truth (>= 50 % of their points on one instance)", std::to_string(s.known));
  line("  planar / structure (the database's flags)",
       absl::StrFormat("%d / %d", s.planar, s.structure));
  line("  on true structure (floor, walls) / of them flagged structure",
       absl::StrFormat("%d / %d", s.on_structure, s.on_structure_flagged));
  line("mergeable (neither planar nor structure)", std::to_string(s.mergeable));
  line("object models", std::to_string(s.models));
  line("models from >= 2 segments", std::to_string(s.multi));
  line("  of them at >= 2 places (not one surface under two labels)", std::to_string(s.multi_place));
  line("erroneous merges (kinds differ)", std::to_string(s.erroneous));
  line("structure merges (true structure in a model of >= 2)", std::to_string(s.structure_merges));
  line("repeated kinds' mergeable segments with their kind elsewhere",
       s.repeated == 0 ? std::string("- (no repeated kind)")
                       : absl::StrFormat("%.0f %% (%d of %d)",
                                         100.0 * double(s.with_kind) / double(s.repeated),
                                         s.with_kind, s.repeated));
  line("purity of object placements (mean; under 80 %)",
       s.pure_placements == 0 ? std::string("-")
                              : absl::StrFormat("%.0f %% (%d of %d)", 100.0 * s.placement_purity,
                                                s.impure_placements, s.pure_placements));
  line("purity of object models (mean, least; under 95 %)",
       s.pure_models == 0 ? std::string("-")
                          : absl::StrFormat("%.0f %%, %.0f %% (%d of %d)", 100.0 * s.model_purity,
                                            100.0 * s.model_purity_min, s.impure_models,
                                            s.pure_models));
  for (const auto& i : s.impure) std::printf("  %s\n", i.c_str());
  line("structure leakage (object models' points on floor, walls)",
       s.pure_models == 0 ? std::string("-") : absl::StrFormat("%.1f %%", 100.0 * s.leakage));
  line("excess extent of object models (mean, most; over 5 cm)",
       s.extent_models == 0 ? std::string("-")
                            : absl::StrFormat("%.2f m, %.2f m (%d of %d)", s.extent_excess,
                                              s.extent_excess_max, s.extent_over,
                                              s.extent_models));
  for (const auto& j : s.junk) std::printf("  %s\n", j.c_str());
  // models: how many models the kind ends in over all sessions (the target: at most 2 for a
  // chair kind); models/object: how many models hold each object's segments, on average.
  std::printf("\n%-22s %8s %10s %8s %14s\n", "kind", "objects", "segments", "models",
              "models/object");
  for (const auto& k : s.kinds) {
    std::printf("%-22s %8zu %10zu %8zu %14.2f\n", k.kind.c_str(), k.objects, k.segments,
                k.models, k.models_per_object);
  }
}

CensusScore scoreCensus(const std::vector<Row>& rows) {
  CensusScore s;
  double structure_points = 0.0, all_points = 0.0;
  for (const Row& row : rows) {
    const Eigen::Vector3f spans = principalSpans(row.points);
    const size_t n = row.placements.size();
    s.placements += n;
    all_points += double(row.summary.num_points) * double(n);
    if (row.summary.structure) {
      s.structure += n;
      structure_points += double(row.summary.num_points) * double(n);
      continue;
    }
    s.planar += row.summary.planar ? n : 0;
    s.largest_object_m = std::max(s.largest_object_m, spans(0));
    if (spans(0) >= 0.6f && spans(0) <= CensusScore::kFurniture && spans(2) >= 0.3f) {
      s.chair_sized += n;
    }
    if (spans(0) > CensusScore::kGiant) {
      s.giant += n;
      s.findings.push_back(absl::StrFormat(
          "giant object: model %d, %.2f x %.2f x %.2f m, %d points, %d placement(s), first in %s",
          row.summary.id, spans(0), spans(1), spans(2), row.summary.num_points, n,
          row.placements.empty() ? std::string("-") : row.placements.front().session));
    } else if (spans(0) > CensusScore::kFurniture) {
      s.large += n;
    } else if (spans(0) >= CensusScore::kSmall) {
      s.furniture += n;
    } else {
      s.small += n;
    }
    s.models_at_two_places += places(row) >= 2 ? 1 : 0;
  }
  s.structure_point_share = all_points > 0.0 ? structure_points / all_points : 0.0;
  return s;
}

void printCensusScore(const CensusScore& s) {
  for (const auto& f : s.findings) std::printf("%s\n", f.c_str());
  line("placements (raw segments in the database)", std::to_string(s.placements));
  line("  structure / planar (the database's flags)",
       absl::StrFormat("%d / %d", s.structure, s.planar));
  line("  objects < 0.3 m / 0.3-1.3 m / 1.3-2.5 m (largest span)",
       absl::StrFormat("%d / %d / %d", s.small, s.furniture, s.large));
  line("  giant objects (not structure, > 2.5 m)", std::to_string(s.giant));
  line("  chair-sized (0.6-1.3 m, smallest span >= 0.3 m)", std::to_string(s.chair_sized));
  line("largest object (not structure)", absl::StrFormat("%.2f m", s.largest_object_m));
  line("structure's share of the placements' model points",
       absl::StrFormat("%.0f %%", 100.0 * s.structure_point_share));
  line("objects at >= 2 places", std::to_string(s.models_at_two_places));
}

namespace {

constexpr int kMaxDominantPlanes = 8;
constexpr float kMinDominantShare = 0.02f;
constexpr float kMinDominantArea = 1.0f;  // m²
constexpr size_t kMaxPlanePoints = 150000;  // surface voxels the plane fit looks at

// The voxels (keys) of a scene's dominant planes.
absl::flat_hash_set<uint64_t> dominantPlaneVoxels(const tsdf::TsdfLayer& scene, size_t* planes) {
  const float voxel = scene.voxelSize();
  const int vps = scene.voxelsPerSide();
  std::vector<tsdf::VoxelIndex> surface;
  for (const auto& [b, block] : scene.blocks()) {
    const auto& voxels = block->voxels();
    for (size_t i = 0; i < voxels.size(); ++i) {
      if (!(voxels[i].weight > 0.0f) || !(std::abs(voxels[i].distance) <= 0.5f * voxel)) continue;
      const int x = int(i % size_t(vps)), y = int((i / size_t(vps)) % size_t(vps)),
                z = int(i / (size_t(vps) * size_t(vps)));
      surface.push_back(b * vps + Eigen::Vector3i(x, y, z));
    }
  }
  absl::flat_hash_set<uint64_t> keys;
  *planes = 0;
  if (surface.size() < 100) return keys;
  const size_t step = std::max<size_t>(1, surface.size() / kMaxPlanePoints);
  PointCloud cloud;
  std::vector<tsdf::VoxelIndex> sampled;
  for (size_t i = 0; i < surface.size(); i += step) {
    cloud.points.push_back(scene.voxelCenter(surface[i]));
    sampled.push_back(surface[i]);
  }
  const auto fitted = model::fitPlanes(
      cloud, 2.0f * voxel, 500, kMaxDominantPlanes,
      size_t(std::ceil(kMinDominantShare * float(cloud.points.size()))));
  // Every surface voxel within the fit distance of a plane, in a 4-voxel cell holding one of its
  // sampled inliers, belongs to it (the fit saw a sample; the cells keep a plane to its faces).
  auto cellOf = [](const tsdf::VoxelIndex& v) {
    return packGridKey(tsdf::VoxelIndex(v.x() >> 2, v.y() >> 2, v.z() >> 2));
  };
  for (const auto& plane : fitted) {
    absl::flat_hash_set<uint64_t> cells;
    for (uint32_t i : plane.inliers) cells.insert(cellOf(sampled[i]));
    const Eigen::Vector3f n = plane.coefficients.head<3>();
    std::vector<uint64_t> on;
    for (const auto& v : surface) {
      if (std::abs(n.dot(scene.voxelCenter(v)) + plane.coefficients.w()) > 2.0f * voxel) continue;
      if (cells.count(cellOf(v)) != 0) on.push_back(packGridKey(v));
    }
    // Its faces bigger than an object's can be (a floor, a wall, a partition): connected pieces
    // of the voxel-sized cells its voxels cover, projected onto the plane, of at least
    // kMinDominantArea each. (Table tops at one height are one plane but separate faces.)
    const Eigen::Vector3f a = (std::abs(n.x()) < 0.9f ? Eigen::Vector3f::UnitX()
                                                        : Eigen::Vector3f::UnitY())
                                  .cross(n)
                                  .normalized();
    const Eigen::Vector3f b = n.cross(a);
    auto cell2 = [&](uint64_t key) {
      const Eigen::Vector3f c = scene.voxelCenter(unpackGridKey(key));
      return packGridKey(Eigen::Vector3i(int(std::floor(c.dot(a) / voxel)),
                                         int(std::floor(c.dot(b) / voxel)), 0));
    };
    absl::flat_hash_map<uint64_t, int> component;  // cell → piece (−1: not visited yet)
    for (uint64_t key : on) component[cell2(key)] = -1;
    std::vector<size_t> piece_cells;
    for (auto& [start, id] : component) {
      if (id >= 0) continue;
      const int piece = int(piece_cells.size());
      piece_cells.push_back(0);
      std::vector<uint64_t> stack = {start};
      id = piece;
      while (!stack.empty()) {
        const Eigen::Vector3i c = unpackGridKey(stack.back());
        stack.pop_back();
        ++piece_cells.back();
        for (int dy = -2; dy <= 2; ++dy) {  // across one-cell holes (sensor dropouts)
          for (int dx = -2; dx <= 2; ++dx) {
            const auto it = component.find(packGridKey(c + Eigen::Vector3i(dx, dy, 0)));
            if (it == component.end() || it->second >= 0) continue;
            it->second = piece;
            stack.push_back(it->first);
          }
        }
      }
    }
    const size_t before = keys.size();
    for (uint64_t key : on) {
      const size_t cells_of_piece = piece_cells[size_t(component.at(cell2(key)))];
      if (float(cells_of_piece) * voxel * voxel >= kMinDominantArea) {
        keys.insert(key);
      }
    }
    if (keys.size() > before) ++*planes;
  }
  return keys;
}

}  // namespace

StatusOr<StructureScore> scoreStructure(const storage::Store& store,
                                        const std::vector<Row>& rows) {
  StructureScore s;
  std::set<std::string> sessions;
  for (const Row& row : rows) {
    for (const Placement& p : row.placements) sessions.insert(p.session);
  }
  std::map<std::string, absl::flat_hash_set<uint64_t>> planes;  // session → plane voxels
  float voxel = 0.0f;
  for (const std::string& session : sessions) {
    auto scene = store.scene(session);
    if (absl::IsNotFound(scene.status())) continue;
    if (!scene.ok()) return scene.status();
    size_t n = 0;
    planes[session] = dominantPlaneVoxels(**scene, &n);
    voxel = (*scene)->voxelSize();
    s.planes += n;
    ++s.sessions_with_scene;
  }
  for (const Row& row : rows) {
    bool on_any = false;
    for (const Placement& p : row.placements) {
      ++s.placements;
      s.planar += row.summary.planar ? 1 : 0;
      s.structure += row.summary.structure ? 1 : 0;
      const auto it = planes.find(p.session);
      if (it == planes.end() || row.points.empty()) continue;
      size_t on = 0;
      for (const auto& q : row.points) {
        const Eigen::Vector3f w = (p.T_world_object.cast<float>() * q);
        const Eigen::Vector3i v = (w / voxel).array().floor().cast<int>();
        bool near = false;
        for (int dz = -1; dz <= 1 && !near; ++dz) {
          for (int dy = -1; dy <= 1 && !near; ++dy) {
            for (int dx = -1; dx <= 1 && !near; ++dx) {
              near = it->second.count(packGridKey(v + Eigen::Vector3i(dx, dy, dz))) != 0;
            }
          }
        }
        on += near ? 1 : 0;
      }
      if (2 * on < row.points.size()) continue;
      ++s.on_planes;
      s.on_planes_flagged += row.summary.structure ? 1 : 0;
      on_any = true;
    }
    if (row.placements.size() < 2) continue;
    ++s.multi;
    if (places(row) < 2) continue;
    ++s.multi_place;
    if (on_any) {
      ++s.structure_merges;
      s.findings.push_back(absl::StrFormat(
          "structure merge: object %d (%d places, %s) lies on a dominant plane",
          row.summary.id, places(row),
          row.summary.structure ? "structure" : row.summary.planar ? "planar" : "object"));
    }
  }
  return s;
}

void printStructureScore(const StructureScore& s) {
  for (const auto& f : s.findings) std::printf("%s\n", f.c_str());
  line("placements (raw segments in the database)", std::to_string(s.placements));
  line("  planar / structure (the database's flags)",
       absl::StrFormat("%d / %d", s.planar, s.structure));
  line("dominant planes (sessions with a scene)",
       absl::StrFormat("%d (%d)", s.planes, s.sessions_with_scene));
  line("  placements on them / of them flagged structure",
       absl::StrFormat("%d / %d", s.on_planes, s.on_planes_flagged));
  line("models from >= 2 segments", std::to_string(s.multi));
  line("  of them at >= 2 places (not one surface under two labels)", std::to_string(s.multi_place));
  line("structure merges (on a dominant plane, in a model of >= 2 places)",
       std::to_string(s.structure_merges));
}

}  // namespace objdb::cli
