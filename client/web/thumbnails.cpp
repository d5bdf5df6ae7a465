#include "client/web/thumbnails.h"

#include <cmath>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "absl/strings/str_format.h"
#include "core/sim/renderer.h"

namespace objdb::web {

StatusOr<std::string> renderThumbnail(const TriangleMesh& mesh, int view, int width, int height) {
  if (view < 0 || view >= kThumbnailViews) {
    return absl::InvalidArgumentError(
        absl::StrFormat("thumbnail view %d does not exist (0..%d)", view, kThumbnailViews - 1));
  }
  if (width < 16 || height < 16 || width > 1024 || height > 1024) {
    return absl::InvalidArgumentError(
        absl::StrFormat("thumbnail size %dx%d is out of range (16..1024)", width, height));
  }
  if (mesh.empty()) return absl::FailedPreconditionError("the model has no surface to draw");
  Eigen::Vector3f lo = mesh.vertices.front(), hi = lo;
  Eigen::Vector3d colour = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    lo = lo.cwiseMin(mesh.vertices[i]);
    hi = hi.cwiseMax(mesh.vertices[i]);
    if (i < mesh.colors.size()) {
      colour += Eigen::Vector3d(mesh.colors[i].r, mesh.colors[i].g, mesh.colors[i].b);
    }
  }
  if (!mesh.colors.empty()) colour /= double(mesh.colors.size());
  const Rgb8 albedo = mesh.colors.empty()
                          ? Rgb8{170, 170, 175}
                          : Rgb8{uint8_t(colour.x()), uint8_t(colour.y()), uint8_t(colour.z())};
  const Eigen::Vector3d centre = (0.5f * (lo + hi)).cast<double>();
  const double radius = std::max(0.5 * double((hi - lo).norm()), 0.01);

  Intrinsics k;
  k.width = width;
  k.height = height;
  k.fx = k.fy = 1.2 * std::min(width, height);
  k.cx = 0.5 * (width - 1);
  k.cy = 0.5 * (height - 1);
  // Far enough that the bounding sphere fits the smaller image side with a margin.
  const double distance = 1.15 * radius * k.fx / (0.5 * std::min(width, height));
  const double azimuth = view == 0 ? -0.75 * M_PI : 0.25 * M_PI, elevation = 0.45;
  const Eigen::Vector3d direction(std::cos(elevation) * std::cos(azimuth),
                                  std::cos(elevation) * std::sin(azimuth), std::sin(elevation));
  OBJDB_ASSIGN_OR_RETURN(const Transform T_world_camera,
                         lookAt(centre + distance * direction, centre));

  sim::RenderParams params;
  params.near_m = float(std::max(0.01, distance - 2.0 * radius));
  params.far_m = float(distance + 2.0 * radius);
  params.ambient = 0.35f;
  sim::Renderer renderer(k, params);
  sim::RenderInstance instance;
  instance.mesh = &mesh;
  instance.albedo = albedo;
  sim::RenderOutput out;
  renderer.render({instance}, T_world_camera, &out);

  cv::Mat image(height, width, CV_8UC3);
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const size_t i = size_t(v) * size_t(width) + size_t(u);
      const bool hit = out.depth.data[i] > 0.0f;
      const Rgb8 c = hit ? out.color.data[i] : Rgb8{255, 255, 255};
      image.at<cv::Vec3b>(v, u) = cv::Vec3b(c.b, c.g, c.r);  // OpenCV is BGR
    }
  }
  std::vector<uchar> png;
  if (!cv::imencode(".png", image, png)) return absl::InternalError("PNG encoding failed");
  return std::string(png.begin(), png.end());
}

}  // namespace objdb::web
