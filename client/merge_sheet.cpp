#include "client/merge_sheet.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>

#include "absl/strings/str_format.h"
#include "client/cli_util.h"

namespace objdb::cli {
namespace {

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
  cv::resize(tile, tile, cv::Size(kTileWidth, kSheetRowHeight));
  tile *= 0.35;  // dimmed: the placement's points stand out
  return tile;
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

}  // namespace

void sheetText(cv::Mat* image, const std::string& line, int x, int y, double scale,
               const cv::Scalar& colour) {
  // A line wider than the panel is drawn smaller, never cut (issue 47: "…3 places, objec").
  int baseline = 0;
  const int width =
      cv::getTextSize(line, cv::FONT_HERSHEY_SIMPLEX, scale, 1, &baseline).width;
  const int room = image->cols - x - 4;
  if (width > room && room > 0) scale *= double(room) / double(width);
  cv::putText(*image, line, cv::Point(x, y), cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1,
              cv::LINE_AA);
}

Status drawSheetRow(const Row& row,
                    const std::map<std::string, std::unique_ptr<io::Dataset>>& opened,
                    cv::Mat* out) {
  const cv::Scalar colours[] = {{80, 255, 80}, {255, 120, 255}, {80, 200, 255}, {255, 200, 80},
                                {120, 120, 255}};
  cv::Mat info = (*out)(cv::Rect(0, 0, kInfoWidth, kSheetRowHeight));
  cv::rectangle(info, cv::Rect(0, 0, kInfoWidth, kSheetRowHeight), cv::Scalar(70, 70, 70), 1);
  const auto& s = row.summary;
  const Eigen::Vector3d e = s.bbox_max - s.bbox_min;
  const size_t n = places(row);
  sheetText(&info,
            absl::StrFormat("object %d: %s at %s, %s", s.id,
                            cli::counted(s.observations.size(), "segment"),
                            cli::counted(n, "place"),
                            s.structure ? "STRUCTURE" : s.planar ? "planar" : "object"),
            8, 20, 0.55);
  sheetText(&info,
            absl::StrFormat("extent %.2f x %.2f x %.2f m, %s", e.x(), e.y(), e.z(),
                            cli::counted(s.num_points, "point")),
            8, 42);
  int y = 64;
  for (const auto& m : row.merges) {
    if (y > kSheetRowHeight - 10) break;
    sheetText(&info, m.source, 8, y, 0.4);
    sheetText(&info,
              absl::StrFormat("   e_ICP %.1f mm, e_TSDF %.1f mm, o_TSDF %d, %d scene",
                              1000 * m.icp_rmse_m, 1000 * m.tsdf_rmse_m, m.tsdf_overlap,
                              m.scene_checks),
              8, y + 16, 0.4);
    y += 36;
  }
  cv::Mat cloud_panel = (*out)(cv::Rect(kInfoWidth, 0, kCloudWidth, kSheetRowHeight));
  drawCloud(row.points, &cloud_panel);
  for (size_t t = 0; t < row.placements.size() && t < size_t(kMaxTiles); ++t) {
    const Placement& p = row.placements[t];
    cv::Mat slot = (*out)(cv::Rect(kInfoWidth + kCloudWidth + int(t) * kTileWidth, 0, kTileWidth,
                                   kSheetRowHeight));
    const auto it = opened.find(p.session);
    if (it == opened.end() || p.best_hits == 0) {
      sheetText(&slot, p.session, 8, 20);
      sheetText(&slot, it == opened.end() ? "(no dataset given)" : "(seen in no frame)", 8, 42);
      continue;
    }
    auto frame = it->second->loadFrame(p.best_frame);
    if (!frame.ok()) return frame.status();
    cv::Mat tile = tileOf(*frame);
    depthAgreeingPoints(row.points, frame->T_world_camera.inverse() * p.T_world_object, *frame,
                        it->second->intrinsics(), &tile, colours[t % 5]);
    sheetText(&tile,
              absl::StrFormat("%s frame %d, %d points", p.session, p.best_frame, p.best_hits), 6,
              16, 0.42);
    // Two placements of one session at one place: one surface under two GSM labels, not two
    // objects.
    for (size_t other = 0; other < t; ++other) {
      if (samePlace(row, row.placements[other], p)) {
        sheetText(&tile, absl::StrFormat("same place as placement %d", other + 1), 6, 34, 0.42,
                  cv::Scalar(80, 200, 255));
        break;
      }
    }
    tile.copyTo(slot);
  }
  return absl::OkStatus();
}

}  // namespace objdb::cli
