#include "core/common/intrinsics.h"

#include <cmath>

namespace objdb {

Status Intrinsics::validate() const {
  if (!(width > 0 && width <= kMaxImageSide && height > 0 && height <= kMaxImageSide)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "intrinsics: image size %dx%d is outside 1..%d per side", width, height, kMaxImageSide));
  }
  if (!(std::isfinite(fx) && fx > 0.0 && std::isfinite(fy) && fy > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("intrinsics: focal lengths must be finite and > 0 (fx=%g fy=%g)", fx, fy));
  }
  if (!(std::isfinite(cx) && cx >= 0.0 && cx <= width && std::isfinite(cy) && cy >= 0.0 &&
        cy <= height)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("intrinsics: principal point (%g, %g) is outside the %dx%d image", cx, cy,
                        width, height));
  }
  return absl::OkStatus();
}

Status Intrinsics::checkImageSize(int image_width, int image_height, absl::string_view what) const {
  if (image_width == width && image_height == height) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrFormat("%s is %dx%d but intrinsics are for %dx%d",
                                                    what, image_width, image_height, width,
                                                    height));
}

Intrinsics Intrinsics::vga() { return {640, 480, 525.0, 525.0, 319.5, 239.5}; }

// Tango (Lenovo Phab 2 Pro) depth camera: 224×172 with a ~70° horizontal field of view.
Intrinsics Intrinsics::tango() { return {224, 172, 160.0, 160.0, 111.5, 85.5}; }

StatusOr<Intrinsics> intrinsicsPreset(absl::string_view name) {
  if (name == "vga") return Intrinsics::vga();
  if (name == "tango") return Intrinsics::tango();
  return absl::InvalidArgumentError(
      absl::StrCat("unknown camera preset '", name, "' (known: vga, tango)"));
}

std::string toString(const Intrinsics& k) {
  return absl::StrFormat("%dx%d fx=%.3f fy=%.3f cx=%.3f cy=%.3f", k.width, k.height, k.fx, k.fy,
                         k.cx, k.cy);
}

}  // namespace objdb
