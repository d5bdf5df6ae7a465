// `objdb info`: describes dataset folders (objdb or TUM layout, or a folder of sessions such as
// the lounge preset): frames, camera, trajectory, ground-truth objects and their visibility.
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "client/cli_util.h"
#include "client/commands.h"
#include "client/progress.h"
#include "core/io/dataset.h"
#include "core/io/image_io.h"
#include "core/io/objdb_dataset.h"

namespace objdb {
namespace {

constexpr const char* kUsage = R"(usage: objdb info PATH [--no-visibility] [--min-pixels N]

Describes a dataset folder (objdb or TUM layout) or a folder of sessions (e.g. the lounge
preset written by `objdb sim`): frames, camera, trajectory length, ground-truth objects by kind
and in how many frames each object is visible (from instances/, objdb layout only).

  --no-visibility   skip reading the instance masks
  --min-pixels N    pixels an object must cover to count as visible (default 0.5 % of the image)
)";

namespace fs = std::filesystem;

int describeDataset(const fs::path& path, bool visibility, int min_pixels_arg) {
  auto opened = io::openDataset(path);
  if (!opened.ok()) {
    std::fprintf(stderr, "objdb info: %s\n", std::string(opened.status().message()).c_str());
    return 1;
  }
  const io::Dataset& ds = **opened;
  const Intrinsics& k = ds.intrinsics();
  std::printf("%s  (%s layout)\n", path.string().c_str(), ds.layout().c_str());
  std::printf("  camera      %s, depth unit %.4g m\n", toString(k).c_str(), ds.metresPerDepthUnit());
  std::printf("  frames      %zu%s%s\n", ds.size(), ds.hasColor() ? ", colour" : "",
              ds.hasInstances() ? ", ground-truth instances" : "");
  if (ds.size() == 0) return 0;

  std::vector<io::GroundTruthObject> objects;
  if (ds.layout() == "objdb") objects = static_cast<const io::ObjdbDataset&>(ds).objects();
  const bool count_visibility = visibility && ds.hasInstances() && !objects.empty();
  const int min_pixels = min_pixels_arg > 0 ? min_pixels_arg : std::max(1, k.width * k.height / 200);
  std::map<int, int> visible_frames;
  double length = 0.0, first_t = 0.0, last_t = 0.0;
  Eigen::Vector3d last_p = Eigen::Vector3d::Zero();
  size_t valid_pixels = 0, total_pixels = 0;
  cli::ProgressBar bar("  reading", ds.size());
  for (size_t i = 0; i < ds.size(); ++i) {
    auto frame = ds.loadFrame(i);
    if (!frame.ok()) {
      std::fprintf(stderr, "objdb info: %s\n", std::string(frame.status().message()).c_str());
      return 1;
    }
    const Eigen::Vector3d p = frame->T_world_camera.translation();
    if (i > 0) length += (p - last_p).norm();
    last_p = p;
    if (i == 0) first_t = frame->timestamp;
    last_t = frame->timestamp;
    for (float d : frame->depth.data) valid_pixels += isValidDepth(d) ? 1 : 0;
    total_pixels += frame->depth.data.size();
    if (count_visibility && frame->instances) {
      std::map<int, int> pixels;
      for (uint16_t id : frame->instances->data) {
        if (id) ++pixels[id];
      }
      for (const auto& [id, n] : pixels) {
        if (n >= min_pixels) ++visible_frames[id];
      }
    }
    bar.update(i + 1);
  }
  bar.finish();
  std::printf("  trajectory  %.2f m over %.1f s; %.1f %% of depth pixels valid\n", length,
              last_t - first_t, 100.0 * double(valid_pixels) / double(std::max<size_t>(total_pixels, 1)));
  if (!objects.empty()) {
    std::map<std::string, int> per_kind;
    for (const auto& o : objects) {
      if (!o.is_structure) ++per_kind[o.category];
    }
    const size_t structure = objects.size() - [&] {
      size_t n = 0;
      for (const auto& [kind, count] : per_kind) n += size_t(count);
      return n;
    }();
    std::printf("  objects     %zu (+%zu structure)", objects.size() - structure, structure);
    std::printf(" of %zu kinds:", per_kind.size());
    for (const auto& [kind, n] : per_kind) std::printf(" %s %d,", kind.c_str(), n);
    std::printf("\n");
    if (count_visibility) {
      std::printf("  %-5s %-18s %-26s %s\n", "id", "kind", "position (m)", "frames visible");
      for (const auto& o : objects) {
        const Eigen::Vector3d t = o.T_world_object.translation();
        std::printf("  %-5d %-18s (%6.2f %6.2f %6.2f)     %d\n", o.id, o.category.c_str(), t.x(),
                    t.y(), t.z(), visible_frames[o.id]);
      }
    }
  }
  return 0;
}

int describeCollection(const fs::path& root, bool visibility, int min_pixels) {
  const std::vector<fs::path> sessions = cli::datasetSubfolders(root);
  if (sessions.empty()) {
    std::fprintf(stderr,
                 "objdb info: %s is neither a dataset (no poses.txt or depth.txt) nor a folder "
                 "of datasets\n",
                 root.string().c_str());
    return 1;
  }
  const fs::path index = root / "objects.json";
  if (fs::exists(index)) {
    try {
      std::ifstream in(index);
      const auto j = nlohmann::json::parse(in);
      std::map<std::string, int> per_kind, structure;
      int n = 0;
      for (const auto& o : j.at("objects")) {
        const auto kind = o.at("category").get<std::string>();
        if (o.value("structure", false)) {
          ++structure[kind];
          continue;
        }
        ++n;
        ++per_kind[kind];
      }
      std::printf("%s: %zu sessions, %d objects of %zu kinds:", root.string().c_str(),
                  sessions.size(), n, per_kind.size());
      for (const auto& [kind, count] : per_kind) std::printf(" %s %d,", kind.c_str(), count);
      std::printf(" and structure:");
      for (const auto& [kind, count] : structure) std::printf(" %s %d,", kind.c_str(), count);
      std::printf("\n\n");
    } catch (const std::exception& e) {
      std::fprintf(stderr, "objdb info: %s: %s\n", index.string().c_str(), e.what());
      return 1;
    }
  }
  int rc = 0;
  for (const auto& s : sessions) {
    rc = std::max(rc, describeDataset(s, visibility, min_pixels));
    std::printf("\n");
  }
  return rc;
}

}  // namespace

int runInfoCommand(int argc, char** argv) {
  std::string path;
  bool visibility = true;
  int min_pixels = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::printf("%s", kUsage);
      return 0;
    } else if (a == "--no-visibility") {
      visibility = false;
    } else if (a == "--min-pixels") {
      long long n = 0;
      if (i + 1 >= argc || !cli::parseInt(argv[++i], 1, 1 << 26, &n)) {
        return cli::usageError("info", "--min-pixels needs a positive integer", kUsage);
      }
      min_pixels = int(n);
    } else if (!a.empty() && a[0] != '-' && path.empty()) {
      path = a;
    } else {
      return cli::usageError("info", "unexpected argument '" + a + "'", kUsage);
    }
  }
  if (path.empty()) {
    return cli::usageError("info", "a dataset PATH is required", kUsage);
  }
  if (!fs::is_directory(path)) {
    std::fprintf(stderr, "objdb info: %s is not a folder\n", path.c_str());
    return 1;
  }
  if (cli::isDatasetDir(path)) return describeDataset(path, visibility, min_pixels);
  return describeCollection(path, visibility, min_pixels);
}

}  // namespace objdb
