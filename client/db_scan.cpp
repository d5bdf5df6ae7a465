#include "client/db_scan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include <opencv2/imgproc.hpp>

#include "core/model/object_model.h"

namespace objdb::cli {

bool samePlace(const Row& row, const Placement& a, const Placement& b) {
  return model::samePlace(a.session, a.T_world_object, b.session, b.T_world_object, row.centre);
}

size_t places(const Row& row) {
  std::vector<std::pair<std::string, Transform>> poses;
  for (const auto& p : row.placements) poses.emplace_back(p.session, p.T_world_object);
  return model::countPlaces(poses, row.centre);
}

size_t depthAgreeingPoints(const std::vector<Eigen::Vector3f>& points,
                           const Transform& T_camera_object, const Frame& frame,
                           const Intrinsics& k, cv::Mat* draw, const cv::Scalar& colour,
                           std::map<int, size_t>* votes, std::vector<PointVote>* point_votes) {
  const Eigen::Isometry3f T = T_camera_object.cast<float>();
  size_t n = 0;
  const float sx = draw ? float(draw->cols) / float(k.width) : 1.0f;
  const float sy = draw ? float(draw->rows) / float(k.height) : 1.0f;
  if (point_votes != nullptr) point_votes->resize(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3f c = T * points[i];
    if (!(c.z() > 0.05f)) continue;
    const int u = int(std::lround(k.fx * c.x() / c.z() + k.cx));
    const int v = int(std::lround(k.fy * c.y() / c.z() + k.cy));
    if (u < 0 || v < 0 || u >= k.width || v >= k.height) continue;
    const float d = frame.depth.at(u, v);
    if (!(d > 0.0f) || std::abs(d - c.z()) > std::max(0.03f, 0.02f * c.z())) continue;
    ++n;
    if (votes != nullptr && frame.instances) ++(*votes)[int(frame.instances->at(u, v))];
    if (point_votes != nullptr && frame.instances) {
      (*point_votes)[i].add(int(frame.instances->at(u, v)));
    }
    if (draw != nullptr) {
      cv::circle(*draw, cv::Point(int(float(u) * sx), int(float(v) * sy)), 1, colour, -1);
    }
  }
  return n;
}

StatusOr<std::vector<Row>> loadRows(const storage::Store& store, size_t min_placements,
                                    size_t max_rows) {
  std::vector<Row> rows;
  storage::ModelQuery query;
  query.limit = 1000;
  while (true) {
    OBJDB_ASSIGN_OR_RETURN(std::vector<storage::ModelSummary> page, store.modelSummaries(query));
    for (auto& m : page) {
      if (m.observations.size() < min_placements) continue;
      Row row;
      row.centre = 0.5 * (m.bbox_min + m.bbox_max);  // model::placeCentre of its cloud
      row.summary = std::move(m);
      rows.push_back(std::move(row));
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
    const size_t step = std::max<size_t>(1, cloud.size() / kMaxScanPoints);
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

Status scanFrames(const std::map<std::string, std::string>& datasets, size_t every,
                  std::vector<Row>* rows,
                  std::map<std::string, std::unique_ptr<io::Dataset>>* opened) {
  for (const auto& [session, folder] : datasets) {
    OBJDB_ASSIGN_OR_RETURN(std::unique_ptr<io::Dataset> ds, io::openDataset(folder));
    for (size_t f = 0; f < ds->size(); f += every) {
      OBJDB_ASSIGN_OR_RETURN(const Frame frame, ds->loadFrame(f));
      const Transform T_camera_world = frame.T_world_camera.inverse();
      for (Row& row : *rows) {
        for (Placement& p : row.placements) {
          if (p.session != session) continue;
          const size_t n = depthAgreeingPoints(row.points, T_camera_world * p.T_world_object,
                                               frame, ds->intrinsics(), nullptr, {}, &p.votes,
                                               &p.point_votes);
          if (n > p.best_hits) {
            p.best_hits = n;
            p.best_frame = f;
          }
        }
      }
    }
    std::fprintf(stderr, "session %s: %zu frames of %s looked at\n", session.c_str(),
                 ds->size(), folder.c_str());
    if (opened != nullptr) (*opened)[session] = std::move(ds);
  }
  return absl::OkStatus();
}

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

}  // namespace objdb::cli
