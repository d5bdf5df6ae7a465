// `objdb segment`: segments one dataset frame (paper §III-A) and writes every intermediate map as
// a PNG, like the paper's Fig. 3: depth, filtered depth, discontinuities, convexity, normals,
// boundaries, labels and the labels over the colour image; prints per-step timings and segments.
#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "client/cli_util.h"
#include "client/commands.h"
#include "core/io/dataset.h"
#include "core/segmentation/depth_segmenter.h"

namespace objdb {
namespace {

namespace fs = std::filesystem;
using segmentation::DepthSegmenter;
using segmentation::SegmentationMaps;
using segmentation::SegmentationResult;

constexpr const char* kUsage =
    R"(usage: objdb segment --dataset DIR --frame N --out DIR [--config FILE]

Segments frame N (0-based) of a dataset (objdb or TUM layout) with the geometric depth
segmentation of paper §III-A and writes its steps as PNG images to DIR (paper Fig. 3):
  depth.png           input depth, colour-mapped (invalid = black)
  filtered_depth.png  depth after the optional hole filling (same colour scale)
  discontinuities.png depth-discontinuity edges (white)
  convexity.png       min-convexity map, grey: black = −1 (strongly concave), white = 1 (convex)
  normals.png         normals as RGB = (n + 1) / 2 (unknown = black)
  boundaries.png      discontinuity ∪ concave ∪ invalid (white)
  labels.png          one stable colour per segment label (no segment = black)
  overlay.png         labels blended over the colour image (datasets with colour only)
and prints the per-step timings and the segment sizes.

  --dataset DIR   dataset folder
  --frame N       frame index, 0 .. frames − 1
  --out DIR       output folder (created if missing; files are overwritten)
  --config FILE   JSON parameters; its "segmentation" section is used (default: built-in)
  -h, --help      this text
)";

struct SegmentArgs {
  std::string dataset, out, config;
  long long frame = -1;
};

int usageError(const std::string& message) { return cli::usageError("segment", message, kUsage); }

int reportError(const Status& status) { return cli::reportError("segment", status); }


// --- Pictures (BGR for OpenCV)
// --------------------------------------------------------------------

// Depth colour-mapped over [lo, hi]; invalid pixels black.
cv::Mat depthPicture(const DepthImage& depth, float lo, float hi) {
  cv::Mat grey(depth.height, depth.width, CV_8U);
  const float scale = hi > lo ? 255.0f / (hi - lo) : 0.0f;
  for (size_t i = 0; i < depth.data.size(); ++i) {
    const float d = depth.data[i];
    grey.data[i] = isValidDepth(d) ? uint8_t(std::clamp((d - lo) * scale, 0.0f, 255.0f)) : 0;
  }
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_JET);
  for (size_t i = 0; i < depth.data.size(); ++i) {
    if (!isValidDepth(depth.data[i])) colour.at<cv::Vec3b>(int(i)) = cv::Vec3b(0, 0, 0);
  }
  return colour;
}

cv::Mat maskPicture(const segmentation::MaskImage& mask) {
  cv::Mat out(mask.height, mask.width, CV_8U);
  for (size_t i = 0; i < mask.data.size(); ++i) out.data[i] = mask.data[i] ? 255 : 0;
  return out;
}

cv::Mat convexityPicture(const Image<float>& convexity) {
  cv::Mat out(convexity.height, convexity.width, CV_8U);
  for (size_t i = 0; i < convexity.data.size(); ++i) {
    const float c = std::isfinite(convexity.data[i]) ? convexity.data[i] : -1.0f;
    out.data[i] = uint8_t(std::lround(std::clamp((c + 1.0f) * 0.5f, 0.0f, 1.0f) * 255.0f));
  }
  return out;
}

cv::Mat normalsPicture(const segmentation::NormalImage& normals) {
  cv::Mat out(normals.height, normals.width, CV_8UC3, cv::Scalar(0, 0, 0));
  for (size_t i = 0; i < normals.data.size(); ++i) {
    const Eigen::Vector3f& n = normals.data[i];
    if (n.isZero() || !n.allFinite()) continue;
    auto channel = [](float x) {
      return uint8_t(std::lround(std::clamp((x + 1.0f) * 0.5f, 0.0f, 1.0f) * 255.0f));
    };
    out.at<cv::Vec3b>(int(i)) = cv::Vec3b(channel(n.z()), channel(n.y()), channel(n.x()));
  }
  return out;
}

// A stable, well-separated, never-dark colour per label (BGR): hue by the golden ratio.
cv::Vec3b labelColour(int32_t label) {
  const double hue = std::fmod(double(label) * 0.618033988749895, 1.0) * 180.0;  // OpenCV hue
  const uint8_t saturation = uint8_t(label % 2 ? 220 : 160);
  cv::Mat hsv(1, 1, CV_8UC3, cv::Scalar(hue, saturation, 255)), bgr;
  cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
  return bgr.at<cv::Vec3b>(0, 0);
}

cv::Mat labelsPicture(const segmentation::LabelImage& labels, int32_t max_label) {
  std::vector<cv::Vec3b> palette(size_t(max_label) + 1, cv::Vec3b(0, 0, 0));
  for (int32_t l = 1; l <= max_label; ++l) palette[size_t(l)] = labelColour(l);
  cv::Mat out(labels.height, labels.width, CV_8UC3);
  for (size_t i = 0; i < labels.data.size(); ++i) {
    const int32_t l = labels.data[i];
    out.at<cv::Vec3b>(int(i)) = l > 0 && l <= max_label ? palette[size_t(l)] : cv::Vec3b(0, 0, 0);
  }
  return out;
}

cv::Mat overlayPicture(const ColorImage& color, const cv::Mat& labels_bgr,
                       const segmentation::LabelImage& labels) {
  cv::Mat out(color.height, color.width, CV_8UC3);
  for (size_t i = 0; i < color.data.size(); ++i) {
    const Rgb8 c = color.data[i];
    cv::Vec3b bgr(c.b, c.g, c.r);
    if (labels.data[i] > 0) {
      const cv::Vec3b l = labels_bgr.at<cv::Vec3b>(int(i));
      for (int k = 0; k < 3; ++k) bgr[k] = uint8_t((int(bgr[k]) + int(l[k]) + 1) / 2);
    }
    out.at<cv::Vec3b>(int(i)) = bgr;
  }
  return out;
}

Status writePng(const fs::path& path, const cv::Mat& image) {
  try {
    if (cv::imwrite(path.string(), image)) return absl::OkStatus();
    return absl::UnavailableError("cannot write " + path.string());
  } catch (const cv::Exception& e) {
    return absl::UnavailableError("cannot write " + path.string() + ": " + e.what());
  }
}

double msSince(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace

int runSegmentCommand(int argc, char** argv) {
  SegmentArgs args;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::printf("%s", kUsage);
      return 0;
    }
    if (a != "--dataset" && a != "--frame" && a != "--out" && a != "--config") {
      return usageError("unknown option '" + a + "'");
    }
    if (i + 1 >= argc) return usageError(a + " needs a value");
    const char* v = argv[++i];
    if (a == "--dataset") {
      args.dataset = v;
    } else if (a == "--out") {
      args.out = v;
    } else if (a == "--config") {
      args.config = v;
    } else if (!cli::parseInt(v, 0, 1LL << 40, &args.frame)) {
      return usageError(std::string("--frame needs a non-negative integer, got \"") + v + "\"");
    }
  }
  if (args.dataset.empty()) return usageError("--dataset DIR is required");
  if (args.frame < 0) return usageError("--frame N is required");
  if (args.out.empty()) return usageError("--out DIR is required");

  StatusOr<Params> loaded = cli::loadParams(args.config);
  if (!loaded.ok()) return reportError(annotate(loaded.status(), "bad config"));
  const Params params = *std::move(loaded);

  const auto start = std::chrono::steady_clock::now();
  StatusOr<std::unique_ptr<io::Dataset>> opened = io::openDataset(args.dataset);
  if (!opened.ok()) return reportError(opened.status());
  const io::Dataset& dataset = **opened;
  if (dataset.size() == 0) {
    return reportError(absl::OutOfRangeError(
        absl::StrFormat("frame %d is out of range: %s has no frames", args.frame, args.dataset)));
  }
  if (size_t(args.frame) >= dataset.size()) {
    return reportError(absl::OutOfRangeError(
        absl::StrFormat("frame %d is out of range: %s has %d frames (0..%d)", args.frame,
                        args.dataset, dataset.size(), dataset.size() - 1)));
  }
  StatusOr<Frame> frame = dataset.loadFrame(size_t(args.frame));
  if (!frame.ok()) return reportError(frame.status());
  const double load_ms = msSince(start);

  StatusOr<DepthSegmenter> segmenter =
      DepthSegmenter::create(params.segmentation, dataset.intrinsics());
  if (!segmenter.ok()) return reportError(segmenter.status());
  SegmentationMaps maps;
  const ColorImage* color = frame->color ? &*frame->color : nullptr;
  StatusOr<SegmentationResult> result = segmenter->segment(frame->depth, color, &maps);
  if (!result.ok())
    return reportError(annotate(result.status(), "frame " + std::to_string(args.frame)));

  const fs::path out = args.out;
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec)
    return reportError(
        absl::UnavailableError("cannot create " + out.string() + ": " + ec.message()));

  // One colour scale for both depth pictures: the input's valid range.
  float lo = std::numeric_limits<float>::infinity(), hi = 0.0f;
  for (float d : frame->depth.data) {
    if (isValidDepth(d)) lo = std::min(lo, d), hi = std::max(hi, d);
  }
  if (!(hi > 0.0f)) lo = hi = 0.0f;
  const auto t_write = std::chrono::steady_clock::now();
  const cv::Mat labels = labelsPicture(result->labels, int32_t(result->segments.size()));
  std::vector<std::pair<std::string, cv::Mat>> pictures = {
      {"depth.png", depthPicture(frame->depth, lo, hi)},
      {"filtered_depth.png", depthPicture(maps.depth, lo, hi)},
      {"discontinuities.png", maskPicture(maps.discontinuities)},
      {"convexity.png", convexityPicture(maps.convexity)},
      {"normals.png", normalsPicture(maps.normals)},
      {"boundaries.png", maskPicture(maps.boundaries)},
      {"labels.png", labels}};
  if (color) pictures.push_back({"overlay.png", overlayPicture(*color, labels, result->labels)});
  for (const auto& [name, picture] : pictures) {
    if (Status s = writePng(out / name, picture); !s.ok()) return reportError(s);
  }
  const double write_ms = msSince(t_write);

  const auto& t = result->timings;
  const size_t n_pixels = frame->depth.data.size();
  std::printf("%s frame %lld: %dx%d, depth %.3f..%.3f m\n", args.dataset.c_str(), args.frame,
              frame->depth.width, frame->depth.height, double(lo), double(hi));
  std::printf(
      "timings (ms): load %.1f | points %.1f  discontinuities %.1f  normals %.1f  "
      "convexity %.1f  labels %.1f  segments %.1f  = segmentation %.1f | write %.1f\n",
      load_ms, t.filter_ms + t.points_ms, t.discontinuity_ms, t.normals_ms, t.convexity_ms, t.labels_ms,
      t.segments_ms, t.total_ms, write_ms);
  std::printf(
      "pixels: %zu invalid, %zu boundary (%.1f %% / %.1f %%); %zu regions below %d px "
      "dropped\n",
      result->invalid_pixels, result->boundary_pixels,
      100.0 * double(result->invalid_pixels) / double(n_pixels),
      100.0 * double(result->boundary_pixels) / double(n_pixels), result->dropped_small,
      segmenter->minSegmentPixels());
  std::vector<const segmentation::Segment*> by_size;
  for (const auto& s : result->segments) by_size.push_back(&s);
  std::sort(by_size.begin(), by_size.end(),
            [](const auto* a, const auto* b) { return a->pixels.size() > b->pixels.size(); });
  std::printf("segments: %zu\n", by_size.size());
  for (const auto* s : by_size) {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const auto& p : s->points) mean += p.cast<double>();
    mean /= double(std::max<size_t>(1, s->points.size()));
    std::printf("  label %4d  %8zu px  %5.1f %%  centre (%6.2f %6.2f %6.2f) m", s->label,
                s->pixels.size(), 100.0 * double(s->pixels.size()) / double(n_pixels), mean.x(),
                mean.y(), mean.z());
    if (s->mean_color) {
      std::printf("  colour (%3d %3d %3d)", s->mean_color->r, s->mean_color->g, s->mean_color->b);
    }
    std::printf("\n");
  }
  std::printf("written %zu images to %s\n", pictures.size(), out.string().c_str());
  return 0;
}

}  // namespace objdb
