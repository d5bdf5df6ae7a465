#include "client/eval_completion.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>

#include "absl/strings/str_format.h"
#include "core/common/mesh_distance.h"
#include "core/completion/completion_score.h"
#include "core/io/dataset.h"
#include "core/sim/scene.h"

namespace objdb::cli {
namespace {

namespace fs = std::filesystem;

constexpr float kTolerance = 0.02f;  // 2 cm, as the GSM and database issues score surfaces
constexpr size_t kFramesChecked = 100;  // per session, spread evenly over it
constexpr size_t kBaselinePoints = 20000;  // measured vertices checked the same way

double percent(size_t part, size_t whole) {
  return whole == 0 ? 0.0 : 100.0 * double(part) / double(whole);
}

// Every session's simulator scene, when every session folder has its scene.json.
struct Truth {
  std::map<std::string, sim::BuiltScene> built;  // session → its true surfaces
  std::vector<completion::TrueInstance> objects;  // non-structure instances, all sessions
};

StatusOr<bool> readTruth(const std::vector<SessionMeshes>& meshes,
                         const std::map<std::string, std::string>& folders, Truth* truth) {
  for (const auto& m : meshes) {
    const fs::path file = fs::path(folders.at(m.session)) / "scene.json";
    if (!fs::exists(file)) return false;
  }
  for (const auto& m : meshes) {
    const fs::path file = fs::path(folders.at(m.session)) / "scene.json";
    OBJDB_ASSIGN_OR_RETURN(const sim::Scene scene, sim::loadSceneFile(file));
    OBJDB_ASSIGN_OR_RETURN(sim::BuiltScene built, sim::buildScene(scene));
    truth->built.emplace(m.session, std::move(built));
    std::map<int, const sim::SceneObject*> objects;
    for (const auto& o : scene.objects) objects[o.id] = &o;
    for (const auto& instance : truth->built.at(m.session).instances) {
      const auto o = objects.find(int(instance.instance_id));
      if (o == objects.end() || o->second->structure) continue;
      truth->objects.push_back({m.session, o->second->category, o->second->id, instance.mesh,
                                instance.T_world_object});
    }
  }
  return true;
}

}  // namespace

Status printCompletionScore(const std::vector<SessionMeshes>& meshes,
                            const std::map<std::string, std::string>& folders) {
  Truth truth;
  OBJDB_ASSIGN_OR_RETURN(const bool with_truth, readTruth(meshes, folders, &truth));
  std::map<std::string, MeshDistance> measured_of, completed_of;
  for (const auto& m : meshes) {
    OBJDB_ASSIGN_OR_RETURN(auto measured, MeshDistance::create(m.measured, kTolerance));
    OBJDB_ASSIGN_OR_RETURN(auto completed, MeshDistance::create(m.completed, kTolerance));
    measured_of.emplace(m.session, std::move(measured));
    completed_of.emplace(m.session, std::move(completed));
  }
  std::printf("\nscene completion (GetSceneMesh, measured and completed; surface farther than "
              "2 cm from the measured mesh counts as added):\n");
  std::printf("%-24s %9s %9s %9s %10s %10s %9s %10s\n", "session", "vertices", "added",
              "through", "on depth", "other ses.", "on truth", "measured");
  size_t all_added = 0, all_through = 0, all_on_depth = 0, all_other = 0, all_truth = 0;
  size_t all_measured = 0, all_measured_through = 0;
  for (const auto& m : meshes) {
    const auto added = completion::addedVertices(m.completed, measured_of.at(m.session));
    // The session's own frames, spread over it.
    OBJDB_ASSIGN_OR_RETURN(const auto dataset, io::openDataset(folders.at(m.session)));
    completion::FrameChecker checker(added);
    // The same check on the measured surface (a sample) is its baseline: noise and fusion put
    // some true surface in front of single frames' depth too.
    std::vector<Eigen::Vector3f> sample;
    const size_t every = std::max<size_t>(1, m.measured.vertices.size() / kBaselinePoints);
    for (size_t i = 0; i < m.measured.vertices.size(); i += every) {
      sample.push_back(m.measured.vertices[i]);
    }
    completion::FrameChecker baseline(std::move(sample));
    const size_t step = std::max<size_t>(1, dataset->size() / kFramesChecked);
    for (size_t i = 0; i < dataset->size(); i += step) {
      OBJDB_ASSIGN_OR_RETURN(const Frame frame, dataset->loadFrame(i));
      checker.add(frame, dataset->intrinsics());
      baseline.add(frame, dataset->intrinsics());
    }
    const completion::FrameEvidence evidence = checker.evidence();
    const completion::FrameEvidence measured = baseline.evidence();
    // Another session's measured surface there.
    size_t other = 0;
    for (const auto& v : added) {
      other += std::any_of(measured_of.begin(), measured_of.end(),
                           [&](const auto& s) {
                             return s.first != m.session && s.second.distance(v) <= kTolerance;
                           })
                   ? 1
                   : 0;
    }
    size_t on_truth = 0;
    if (with_truth) {
      OBJDB_ASSIGN_OR_RETURN(const auto index,
                             MeshDistance::create(sim::trueSurface(truth.built.at(m.session)), kTolerance));
      for (const auto& v : added) on_truth += index.distance(v) <= kTolerance ? 1 : 0;
    }
    std::printf("%-24s %9zu %9zu %8.1f%% %9.1f%% %10s %9s %9.1f%%\n", m.session.c_str(),
                m.completed.vertices.size(), added.size(), percent(evidence.seen_through, added.size()),
                percent(evidence.seen_on_surface, added.size()),
                meshes.size() < 2 ? "-" : absl::StrFormat("%.1f%%", percent(other, added.size())).c_str(),
                with_truth ? absl::StrFormat("%.1f%%", percent(on_truth, added.size())).c_str() : "-",
                percent(measured.seen_through, measured.points));
    all_measured += measured.points;
    all_measured_through += measured.seen_through;
    all_added += added.size();
    all_through += evidence.seen_through;
    all_on_depth += evidence.seen_on_surface;
    all_other += other;
    all_truth += on_truth;
  }
  std::printf("%-24s %9s %9zu %8.1f%% %9.1f%% %10s %9s %9.1f%%\n", "all", "", all_added,
              percent(all_through, all_added), percent(all_on_depth, all_added),
              meshes.size() < 2 ? "-" : absl::StrFormat("%.1f%%", percent(all_other, all_added)).c_str(),
              with_truth ? absl::StrFormat("%.1f%%", percent(all_truth, all_added)).c_str() : "-",
              percent(all_measured_through, all_measured));
  std::printf("through: seen through by the session's own frames (%zu per session at most; more "
              "of them saw it in front of the measured depth by > max(3 cm, 2 %%) than on it), so "
              "wrong; on depth: on a measured depth there; other ses.: within 2 cm of another session's measured "
              "surface; on truth: within 2 cm of a true surface (scene.json); measured: the same frame "
              "check on the measured mesh (a sample), its baseline\n",
              kFramesChecked);
  if (!with_truth) return absl::OkStatus();
  std::map<std::string, const MeshDistance*> before, after;
  for (const auto& [name, index] : measured_of) before[name] = &index;
  for (const auto& [name, index] : completed_of) after[name] = &index;
  OBJDB_ASSIGN_OR_RETURN(const auto gain,
                         completion::surfaceGain(truth.objects, before, after, kTolerance));
  std::printf("repeated objects' true surface within 2 cm of the reconstruction: %.1f %% before, "
              "%.1f %% after completion (%+.1f points) over %zu instances; ceiling (every "
              "instance of the shape, any session) %.1f %% (%+.1f points)\n",
              100.0 * gain.before, 100.0 * gain.after, 100.0 * (gain.after - gain.before),
              gain.instances.size(), 100.0 * gain.ceiling, 100.0 * (gain.ceiling - gain.before));
  return absl::OkStatus();
}

}  // namespace objdb::cli
