// Pinhole camera intrinsics (no distortion: depth images are expected rectified).
// Pixel (u, v) is the pixel whose centre projects from x = (u − cx)·z / fx, y = (v − cy)·z / fy.
#pragma once

#include <string>

#include <Eigen/Core>

#include "core/common/status.h"

namespace objdb {

// Largest image side accepted anywhere (file, wire, config): bounds every allocation.
inline constexpr int kMaxImageSide = 8192;

struct Intrinsics {
  int width = 0;     // pixels
  int height = 0;    // pixels
  double fx = 0.0;   // focal length in pixels
  double fy = 0.0;   // focal length in pixels
  double cx = 0.0;   // principal point, pixels
  double cy = 0.0;   // principal point, pixels

  // Positive, finite, image within (0, kMaxImageSide], principal point inside the image.
  Status validate() const;

  // Returns a readable error unless the image is width × height.
  Status checkImageSize(int image_width, int image_height, absl::string_view what) const;

  Eigen::Vector3d backProject(double u, double v, double z) const {
    return {(u - cx) * z / fx, (v - cy) * z / fy, z};
  }
  // Projects a camera-frame point with z > 0 to pixel coordinates.
  Eigen::Vector2d project(const Eigen::Vector3d& p_camera) const {
    return {fx * p_camera.x() / p_camera.z() + cx, fy * p_camera.y() / p_camera.z() + cy};
  }
  bool operator==(const Intrinsics&) const = default;

  // Presets: Kinect-style VGA (640×480, f = 525) and the Tango depth camera (224×172).
  static Intrinsics vga();
  static Intrinsics tango();
};

// "vga" / "tango" → preset; anything else is an error naming the accepted names.
StatusOr<Intrinsics> intrinsicsPreset(absl::string_view name);

std::string toString(const Intrinsics& intrinsics);

}  // namespace objdb
