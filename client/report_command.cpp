// `objdb report merges`: a picture sheet of the database's merges, for data without ground truth
// (issue 17). Every model built from two or more segments gets one row: its evidence (surface
// kind, extent, each merge's e_ICP, e_TSDF, o_TSDF and scene checks), its surface cloud, and each
// of its placements drawn over the camera image of the frame that sees it best (most model points
// projecting onto pixels whose measured depth agrees), the rest of the image dimmed. This is how a
// person judges whether a database built from real data merged the right things. Reads the
// database file read-only (also while objdb-server writes it) and the sessions' datasets (any
// layout openDataset reads: objdb, TUM, 7-Scenes).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <cstdint>
#include <map>
#include <set>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_format.h"
#include "client/cli_util.h"
#include "client/commands.h"
#include "core/io/dataset.h"
#include "core/io/ground_truth.h"
#include "storage/sqlite_store.h"

namespace objdb {
namespace {

constexpr const char* kCommand = "report";
constexpr const char* kUsage = R"(usage: objdb report merges --db FILE --out SHEET.png DATASET... [options]
       objdb report truth  --db FILE DATASET... [--every N]

Draws every model built from two or more segments as one row of a PNG sheet: its evidence
(surface kind, extent, each merge's e_ICP, e_TSDF, o_TSDF and scene checks), its surface cloud,
and each placement over the camera image of the frame that sees it best (most model points
landing on pixels whose depth agrees within max(3 cm, 2 % of the depth)); the rest of the image is
dimmed. Each DATASET is one session's folder (objdb, TUM or 7-Scenes layout), named after the
folder as `objdb stream` names sessions, or NAME=FOLDER. Placements in sessions without a dataset
are listed but not drawn. The database is opened read-only.

`truth` scores the database against the datasets' ground truth (instances/ and objects.json, in
the objdb layout or a TUM sequence with them): each placement takes the instance most of its
depth-agreeing points fall on over all frames (none below 50 %), and the report prints the
paper's table (placements, mergeable, models, models from >= 2 segments, erroneous merges:
kinds differ, structure merges: floor or wall in a model of >= 2, the share of repeated kinds'
mergeable segments that share a model with their kind at another place: two placements of one
session within 5 cm are one object under two GSM labels) and models per true object by kind.

  --db FILE         the database (objdb-server's --db, or a backup of it)
  --out FILE.png    the sheet
  --max-rows N      at most N models, the ones with the most placements first (default 40)
  --every N         look for the best view in every N-th frame (default 1)
  -h, --help        show this text

exit status: 0 sheet written; 1 the database, a dataset or the sheet failed; 2 command-line error.
)";

constexpr int kRowHeight = 240, kTileWidth = 320, kInfoWidth = 380, kCloudWidth = 240;
constexpr int kMaxTiles = 5;
constexpr size_t kMaxPoints = 3000;  // model points projected per placement

struct Placement {
  std::string session;
  Transform T_world_object;
  size_t best_frame = 0;
  size_t best_hits = 0;
  std::map<int, size_t> votes;  // ground-truth instance id → points on it, over all frames
};

// Two placements of one session within 5 cm: one surface under two GSM labels, not two objects.
bool samePlace(const Placement& a, const Placement& b) {
  return a.session == b.session &&
         (a.T_world_object.translation() - b.T_world_object.translation()).norm() < 0.05;
}

struct Row {
  storage::ModelSummary summary;
  std::vector<Eigen::Vector3f> points;  // model frame, at most kMaxPoints
  std::vector<database::MergeRecord> merges;
  std::vector<Placement> placements;
};

// Points of `points` (model frame) placed by T_camera_object that land on a pixel of `frame`
// whose depth agrees; with `draw`, those points are drawn onto it in `colour`.
size_t hits(const std::vector<Eigen::Vector3f>& points, const Transform& T_camera_object,
            const Frame& frame, const Intrinsics& k, cv::Mat* draw = nullptr,
            const cv::Scalar& colour = {}, std::map<int, size_t>* votes = nullptr) {
  const Eigen::Isometry3f T = T_camera_object.cast<float>();
  size_t n = 0;
  const float sx = draw ? float(draw->cols) / float(k.width) : 1.0f;
  const float sy = draw ? float(draw->rows) / float(k.height) : 1.0f;
  for (const auto& p : points) {
    const Eigen::Vector3f c = T * p;
    if (!(c.z() > 0.05f)) continue;
    const int u = int(std::lround(k.fx * c.x() / c.z() + k.cx));
    const int v = int(std::lround(k.fy * c.y() / c.z() + k.cy));
    if (u < 0 || v < 0 || u >= k.width || v >= k.height) continue;
    const float d = frame.depth.at(u, v);
    if (!(d > 0.0f) || std::abs(d - c.z()) > std::max(0.03f, 0.02f * c.z())) continue;
    ++n;
    if (votes != nullptr && frame.instances) ++(*votes)[int(frame.instances->at(u, v))];
    if (draw != nullptr) {
      cv::circle(*draw, cv::Point(int(float(u) * sx), int(float(v) * sy)), 1, colour, -1);
    }
  }
  return n;
}

cv::Mat tileOf(const Frame& frame) {
  cv::Mat tile;
  if (frame.color) {
    cv::Mat rgb(frame.color->height, frame.color->width, CV_8UC3,
                const_cast<Rgb8*>(frame.color->data.data()));
    cv::cvtColor(rgb, tile, cv::COLOR_RGB2BGR);
  } else {
    cv::Mat depth(frame.depth.height, frame.depth.width, CV_32F,
                  const_cast<float*>(frame.depth.data.data()));
    cv::Mat grey;
    depth.convertTo(grey, CV_8U, 255.0 / 5.0);
    cv::cvtColor(grey, tile, cv::COLOR_GRAY2BGR);
  }
  cv::resize(tile, tile, cv::Size(kTileWidth, kRowHeight));
  tile *= 0.35;  // dimmed: the placement's points stand out
  return tile;
}

void text(cv::Mat* image, const std::string& line, int x, int y, double scale = 0.45,
          const cv::Scalar& colour = cv::Scalar(235, 235, 235)) {
  cv::putText(*image, line, cv::Point(x, y), cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1,
              cv::LINE_AA);
}

// The cloud seen along its smallest principal axis, shaded by depth along it.
void drawCloud(const std::vector<Eigen::Vector3f>& points, cv::Mat* panel) {
  if (points.size() < 3) return;
  Eigen::Vector3f mean = Eigen::Vector3f::Zero();
  for (const auto& p : points) mean += p;
  mean /= float(points.size());
  Eigen::Matrix3f cov = Eigen::Matrix3f::Zero();
  for (const auto& p : points) cov += (p - mean) * (p - mean).transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> solver(cov);
  const Eigen::Vector3f a = solver.eigenvectors().col(2), b = solver.eigenvectors().col(1),
                        c = solver.eigenvectors().col(0);
  float extent = 1e-3f, depth_lo = 1e9f, depth_hi = -1e9f;
  for (const auto& p : points) {
    extent = std::max({extent, std::abs((p - mean).dot(a)), std::abs((p - mean).dot(b))});
    depth_lo = std::min(depth_lo, (p - mean).dot(c));
    depth_hi = std::max(depth_hi, (p - mean).dot(c));
  }
  const float scale = 0.45f * float(std::min(panel->cols, panel->rows)) / extent;
  for (const auto& p : points) {
    const Eigen::Vector3f q = p - mean;
    const float shade = (q.dot(c) - depth_lo) / std::max(1e-3f, depth_hi - depth_lo);
    cv::circle(*panel,
               cv::Point(panel->cols / 2 + int(q.dot(a) * scale),
                         panel->rows / 2 - int(q.dot(b) * scale)),
               1, cv::Scalar(120 + 120 * shade, 200, 255 - 120 * shade), -1);
  }
}

struct Options {
  std::string db_path, out;
  size_t max_rows = 40, every = 1;
  std::map<std::string, std::string> datasets;  // session → folder
};

// Parses the options both reports take; returns -1 to go on, else the exit status.
int parseOptions(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--db" || a == "--out" || a == "--max-rows" || a == "--every") {
      const char* v = value();
      if (v == nullptr) return cli::usageError(kCommand, a + " needs a value", kUsage);
      if (a == "--db") o->db_path = v;
      if (a == "--out") o->out = v;
      if (a == "--max-rows" || a == "--every") {
        const long n = std::strtol(v, nullptr, 10);
        if (n < 1) return cli::usageError(kCommand, a + " must be a whole number >= 1", kUsage);
        (a == "--every" ? o->every : o->max_rows) = size_t(n);
      }
    } else if (!a.empty() && a[0] == '-') {
      return cli::usageError(kCommand, "unknown option " + a, kUsage);
    } else {
      const size_t eq = a.find('=');
      const std::string folder = eq == std::string::npos ? a : a.substr(eq + 1);
      std::string name = eq == std::string::npos
                             ? std::filesystem::path(folder).lexically_normal().filename().string()
                             : a.substr(0, eq);
      if (name.empty()) name = std::filesystem::path(folder).parent_path().filename().string();
      o->datasets[name] = folder;
    }
  }
  return -1;
}

// The active models with at least `min_placements` placements, most placements first, at most
// `max_rows`, with their sampled clouds and merge records.
StatusOr<std::vector<Row>> loadRows(const storage::SqliteStore& store, size_t min_placements,
                                    size_t max_rows) {
  std::vector<Row> rows;
  storage::ModelQuery query;
  query.limit = 1000;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(std::vector<storage::ModelSummary> page, store.modelSummaries(query));
    for (auto& m : page) {
      if (m.observations.size() >= min_placements) rows.push_back({std::move(m), {}, {}, {}});
    }
    if (page.size() < query.limit) break;
    query.after_id = page.back().id;
  }
  std::stable_sort(rows.begin(), rows.end(), [](const Row& a, const Row& b) {
    return a.summary.observations.size() > b.summary.observations.size();
  });
  if (rows.size() > max_rows) rows.resize(max_rows);
  for (Row& row : rows) {
    OBJDB_ASSIGN_OR_RETURN(const auto model, store.model(row.summary.id));
    const auto& cloud = model->cloud.points;
    const size_t step = std::max<size_t>(1, cloud.size() / kMaxPoints);
    for (size_t i = 0; i < cloud.size(); i += step) row.points.push_back(cloud[i]);
    OBJDB_ASSIGN_OR_RETURN(row.merges, store.mergeRecordsInto(row.summary.id));
    for (const auto& o : row.summary.observations) {
      Placement p;
      p.session = o.session;
      p.T_world_object = o.T_world_object;
      row.placements.push_back(std::move(p));
    }
  }
  return rows;
}

// One pass over each session's frames: the best frame of every placement and, where the frames
// have ground-truth instances, the instance votes of its depth-agreeing points.
Status scanFrames(const Options& o, std::vector<Row>* rows,
                  std::map<std::string, std::unique_ptr<io::Dataset>>* opened) {
  for (const auto& [session, folder] : o.datasets) {
    OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<io::Dataset> ds, io::openDataset(folder));
    for (size_t f = 0; f < ds->size(); f += o.every) {
      OBJDB_ASSIGN_OR_RETURN(const Frame frame, ds->loadFrame(f));
      const Transform T_camera_world = frame.T_world_camera.inverse();
      for (Row& row : *rows) {
        for (Placement& p : row.placements) {
          if (p.session != session) continue;
          const size_t n = hits(row.points, T_camera_world * p.T_world_object, frame,
                                ds->intrinsics(), nullptr, {}, &p.votes);
          if (n > p.best_hits) {
            p.best_hits = n;
            p.best_frame = f;
          }
        }
      }
    }
    std::fprintf(stderr, "session %s: %zu frames of %s looked at\n", session.c_str(),
                 ds->size(), folder.c_str());
    (*opened)[session] = std::move(ds);
  }
  return absl::OkStatus();
}

int merges(int argc, char** argv) {
  Options o;
  if (const int parsed = parseOptions(argc, argv, &o); parsed >= 0) return parsed;
  if (o.db_path.empty() || o.out.empty()) {
    return cli::usageError(kCommand, "--db and --out are required", kUsage);
  }
  const std::string& db_path = o.db_path;
  const std::string& out = o.out;
  storage::SqliteStoreOptions options;
  options.read_only = true;
  auto store = storage::SqliteStore::open(db_path, options);
  if (!store.ok()) return cli::reportError(kCommand, store.status());
  auto loaded = loadRows(**store, 2, o.max_rows);
  if (!loaded.ok()) return cli::reportError(kCommand, loaded.status());
  std::vector<Row> rows = *std::move(loaded);
  std::map<std::string, std::unique_ptr<io::Dataset>> opened;
  if (Status scanned = scanFrames(o, &rows, &opened); !scanned.ok()) {
    return cli::reportError(kCommand, scanned);
  }

  const int width = kInfoWidth + kCloudWidth + kMaxTiles * kTileWidth;
  cv::Mat sheet(40 + kRowHeight * int(std::max<size_t>(rows.size(), 1)), width, CV_8UC3,
                cv::Scalar(30, 30, 30));
  text(&sheet,
       absl::StrFormat("%s: %d models built from 2 or more segments (placements over the frame "
                       "that sees them best)",
                       db_path, rows.size()),
       10, 26, 0.6);
  if (rows.empty()) text(&sheet, "no merges", 10, 70, 0.6);
  const cv::Scalar colours[] = {{80, 255, 80}, {255, 120, 255}, {80, 200, 255}, {255, 200, 80},
                                {120, 120, 255}};
  for (size_t r = 0; r < rows.size(); ++r) {
    const Row& row = rows[r];
    const int y0 = 40 + kRowHeight * int(r);
    cv::Mat info = sheet(cv::Rect(0, y0, kInfoWidth, kRowHeight));
    cv::rectangle(info, cv::Rect(0, 0, kInfoWidth, kRowHeight), cv::Scalar(70, 70, 70), 1);
    const auto& s = row.summary;
    const Eigen::Vector3d e = s.bbox_max - s.bbox_min;
    text(&info, absl::StrFormat("object %d: %d placements, %s", s.id, s.observations.size(),
                                s.structure ? "STRUCTURE" : s.planar ? "planar" : "object"),
         8, 20, 0.55);
    text(&info, absl::StrFormat("extent %.2f x %.2f x %.2f m, %d points", e.x(), e.y(), e.z(),
                                s.num_points),
         8, 42);
    int y = 64;
    for (const auto& m : row.merges) {
      if (y > kRowHeight - 10) break;
      text(&info, m.source, 8, y, 0.4);
      text(&info, absl::StrFormat("   e_ICP %.1f mm, e_TSDF %.1f mm, o_TSDF %d, %d scene",
                                  1000 * m.icp_rmse_m, 1000 * m.tsdf_rmse_m, m.tsdf_overlap,
                                  m.scene_checks),
           8, y + 16, 0.4);
      y += 36;
    }
    cv::Mat cloud_panel = sheet(cv::Rect(kInfoWidth, y0, kCloudWidth, kRowHeight));
    drawCloud(row.points, &cloud_panel);
    for (size_t t = 0; t < row.placements.size() && t < size_t(kMaxTiles); ++t) {
      const Placement& p = row.placements[t];
      cv::Mat slot = sheet(cv::Rect(kInfoWidth + kCloudWidth + int(t) * kTileWidth, y0,
                                    kTileWidth, kRowHeight));
      const auto it = opened.find(p.session);
      if (it == opened.end() || p.best_hits == 0) {
        text(&slot, p.session, 8, 20);
        text(&slot, it == opened.end() ? "(no dataset given)" : "(seen in no frame)", 8, 42);
        continue;
      }
      auto frame = it->second->loadFrame(p.best_frame);
      if (!frame.ok()) return cli::reportError(kCommand, frame.status());
      cv::Mat tile = tileOf(*frame);
      hits(row.points, frame->T_world_camera.inverse() * p.T_world_object, *frame,
           it->second->intrinsics(), &tile, colours[t % 5]);
      text(&tile, absl::StrFormat("%s frame %d, %d points", p.session, p.best_frame, p.best_hits),
           6, 16, 0.42);
      // Two placements of one session at one place: one surface under two GSM labels, not two
      // objects.
      for (size_t e = 0; e < t; ++e) {
        if (samePlace(row.placements[e], p)) {
          text(&tile, absl::StrFormat("same place as placement %d", e + 1), 6, 34, 0.42,
               cv::Scalar(80, 200, 255));
          break;
        }
      }
      tile.copyTo(slot);
    }
  }
  if (!cv::imwrite(out, sheet)) {
    return cli::reportError(kCommand,
                            absl::UnavailableError(absl::StrFormat("could not write %s", out)));
  }
  std::printf("%zu models drawn to %s (%dx%d)\n", rows.size(), out.c_str(), sheet.cols,
              sheet.rows);
  return 0;
}


// Ground truth of a placement: the instance most of its depth-agreeing points fell on (0: none
// with >= 50 % of them).
int truthOf(const Placement& p, double* purity) {
  size_t total = 0, best = 0;
  int id = 0;
  for (const auto& [instance, n] : p.votes) {
    total += n;
    if (instance != 0 && n > best) {
      best = n;
      id = instance;
    }
  }
  *purity = total > 0 ? double(best) / double(total) : 0.0;
  return *purity >= 0.5 ? id : 0;
}

int truth(int argc, char** argv) {
  Options o;
  if (const int parsed = parseOptions(argc, argv, &o); parsed >= 0) return parsed;
  if (o.db_path.empty()) return cli::usageError(kCommand, "--db is required", kUsage);
  // Ground truth: objects.json of every session with instances (one id space per session).
  std::map<std::string, std::map<int, io::GroundTruthObject>> objects;
  for (const auto& [session, folder] : o.datasets) {
    auto ds = io::openDataset(folder);
    if (!ds.ok()) return cli::reportError(kCommand, ds.status());
    if (!(*ds)->hasInstances()) {
      return cli::reportError(kCommand, absl::FailedPreconditionError(absl::StrFormat(
                                            "dataset %s has no ground truth (no instances/ "
                                            "folder); `objdb report merges` draws its merges",
                                            folder)));
    }
    auto read = io::readObjectsJson(std::filesystem::path(folder) / "objects.json");
    if (!read.ok()) return cli::reportError(kCommand, read.status());
    for (auto& g : *read) objects[session][g.id] = g;
  }
  storage::SqliteStoreOptions options;
  options.read_only = true;
  auto store = storage::SqliteStore::open(o.db_path, options);
  if (!store.ok()) return cli::reportError(kCommand, store.status());
  auto loaded = loadRows(**store, 1, SIZE_MAX);
  if (!loaded.ok()) return cli::reportError(kCommand, loaded.status());
  std::vector<Row> rows = *std::move(loaded);
  std::map<std::string, std::unique_ptr<io::Dataset>> opened;
  if (Status scanned = scanFrames(o, &rows, &opened); !scanned.ok()) {
    return cli::reportError(kCommand, scanned);
  }
  // Kind of every placement ("" unknown), true structure; counts per kind of mergeable ones.
  struct Truth {
    std::string kind;
    std::string object;  // session/id
    bool structure = false;
  };
  std::vector<std::vector<Truth>> truths(rows.size());
  size_t placements = 0, known = 0, planar = 0, structure = 0, on_structure = 0,
         on_structure_flagged = 0, mergeable = 0, multi = 0, erroneous = 0, structure_merges = 0;
  std::map<std::string, size_t> mergeable_per_kind;
  for (size_t r = 0; r < rows.size(); ++r) {
    const Row& row = rows[r];
    const bool unmatched = row.summary.planar || row.summary.structure;
    for (const Placement& p : row.placements) {
      ++placements;
      double purity = 0.0;
      const int id = truthOf(p, &purity);
      Truth t;
      const auto session = objects.find(p.session);
      if (id != 0 && session != objects.end() && session->second.count(id) != 0) {
        const io::GroundTruthObject& g = session->second.at(id);
        t.kind = g.category;
        t.structure = g.is_structure;
        t.object = absl::StrFormat("%s/%d", p.session, id);
        ++known;
      }
      planar += row.summary.planar ? 1 : 0;
      structure += row.summary.structure ? 1 : 0;
      if (t.structure) {
        ++on_structure;
        on_structure_flagged += row.summary.structure ? 1 : 0;
      }
      if (!unmatched) {
        ++mergeable;
        if (!t.kind.empty() && !t.structure) ++mergeable_per_kind[t.kind];
      }
      truths[r].push_back(t);
    }
    if (row.placements.size() < 2) continue;
    ++multi;
    std::set<std::string> kinds;
    bool has_structure = false;
    for (const Truth& t : truths[r]) {
      if (!t.kind.empty()) kinds.insert(t.kind);
      has_structure = has_structure || t.structure;
    }
    if (kinds.size() > 1) {
      ++erroneous;
      std::string list;
      for (const auto& k : kinds) list += (list.empty() ? "" : " + ") + k;
      std::printf("erroneous merge: object %lld holds %s\n", (long long)row.summary.id,
                  list.c_str());
    }
    if (has_structure) {
      ++structure_merges;
      std::printf("structure merge: object %lld holds a floor or wall placement\n",
                  (long long)row.summary.id);
    }
  }
  // Recall: mergeable placements of kinds with two or more of them that share their model with
  // another placement of their kind at another place.
  size_t repeated = 0, with_kind = 0;
  std::map<std::string, std::set<int64_t>> models_of_object;
  std::map<std::string, std::set<std::string>> objects_of_kind;
  for (size_t r = 0; r < rows.size(); ++r) {
    const Row& row = rows[r];
    if (row.summary.planar || row.summary.structure) continue;
    for (size_t a = 0; a < truths[r].size(); ++a) {
      const Truth& t = truths[r][a];
      if (t.kind.empty() || t.structure) continue;
      models_of_object[t.object].insert(row.summary.id);
      objects_of_kind[t.kind].insert(t.object);
      if (mergeable_per_kind[t.kind] < 2) continue;
      ++repeated;
      // Another placement of its kind elsewhere: one surface under two GSM labels at one place
      // (the same object re-segmented) is not a repeated object found.
      for (size_t b = 0; b < truths[r].size(); ++b) {
        if (b == a || truths[r][b].kind != t.kind) continue;
        if (samePlace(row.placements[a], row.placements[b])) continue;
        ++with_kind;
        break;
      }
    }
  }
  auto line = [](const char* what, const std::string& value) {
    std::printf("%-58s %s\n", what, value.c_str());
  };
  line("placements (raw segments in the database)", std::to_string(placements));
  line("  with ground truth (>= 50 % of their points on one instance)", std::to_string(known));
  line("  planar / structure (the database's flags)",
       absl::StrFormat("%d / %d", planar, structure));
  line("  on true structure (floor, walls) / of them flagged structure",
       absl::StrFormat("%d / %d", on_structure, on_structure_flagged));
  line("mergeable (neither planar nor structure)", std::to_string(mergeable));
  line("object models", std::to_string(rows.size()));
  line("models from >= 2 segments", std::to_string(multi));
  line("erroneous merges (kinds differ)", std::to_string(erroneous));
  line("structure merges (true structure in a model of >= 2)", std::to_string(structure_merges));
  line("repeated kinds' mergeable segments with their kind elsewhere",
       repeated == 0 ? std::string("- (no repeated kind)")
                     : absl::StrFormat("%.0f %% (%d of %d)", 100.0 * double(with_kind) /
                                                                 double(repeated),
                                       with_kind, repeated));
  // Ids are per session: an object seen in three sessions counts three times.
  std::printf("\n%-22s %8s %10s %14s\n", "kind", "objects", "segments", "models/object");
  for (const auto& [kind, ids] : objects_of_kind) {
    size_t models = 0;
    for (const auto& id : ids) models += models_of_object[id].size();
    std::printf("%-22s %8zu %10zu %14.2f\n", kind.c_str(), ids.size(), mergeable_per_kind[kind],
                double(models) / double(ids.size()));
  }
  return 0;
}

}  // namespace

int runReportCommand(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "-h" || std::string(argv[1]) == "--help") {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  if (std::string(argv[1]) == "merges") return merges(argc - 1, argv + 1);
  if (std::string(argv[1]) == "truth") return truth(argc - 1, argv + 1);
  return cli::usageError(kCommand, std::string("unknown report \"") + argv[1] + "\"", kUsage);
}

}  // namespace objdb
