#include "core/io/seven_scenes_dataset.h"

#include <cmath>
#include <map>
#include <optional>
#include <string>

#include <Eigen/SVD>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "core/common/logging.h"
#include "core/io/image_io.h"
#include "core/io/io_util.h"

namespace objdb::io {
namespace {
namespace fs = std::filesystem;

constexpr const char* kIntrinsicsName = "camera-intrinsics.txt";
constexpr const char* kFramePrefix = "frame-";

enum class FrameFileKind { kDepth, kPose, kColor };

struct FrameSuffix {
  const char* text;
  FrameFileKind kind;
};
constexpr FrameSuffix kFrameSuffixes[] = {{".depth.png", FrameFileKind::kDepth},
                                          {".pose.txt", FrameFileKind::kPose},
                                          {".color.png", FrameFileKind::kColor},
                                          {".color.jpg", FrameFileKind::kColor}};

struct FrameFileName {
  uint64_t number = 0;
  FrameFileKind kind = FrameFileKind::kDepth;
  std::string stem;  // "frame-000012", padding as in the file
};

// "frame-000012.depth.png" → frame 12, depth. Not a frame file (nullopt): any other name, so
// notes and other files may sit beside the frames. A number too large for 64 bits is an error.
StatusOr<std::optional<FrameFileName>> parseFrameFileName(const fs::path& file) {
  const std::string name = file.filename().string();
  if (!absl::StartsWith(name, kFramePrefix)) return std::optional<FrameFileName>();
  for (const FrameSuffix& suffix : kFrameSuffixes) {
    if (!absl::EndsWith(name, suffix.text)) continue;
    const size_t prefix_size = std::char_traits<char>::length(kFramePrefix);
    const size_t suffix_size = std::char_traits<char>::length(suffix.text);
    if (name.size() <= prefix_size + suffix_size) break;
    const absl::string_view digits =
        absl::string_view(name).substr(prefix_size, name.size() - prefix_size - suffix_size);
    for (char c : digits) {
      if (!absl::ascii_isdigit(static_cast<unsigned char>(c)))
        return std::optional<FrameFileName>();
    }
    FrameFileName parsed;
    if (!internal::parseUint64(digits, &parsed.number)) {
      return absl::InvalidArgumentError(
          absl::StrCat(file.string(), ": frame number ", digits, " does not fit in 64 bits"));
    }
    parsed.kind = suffix.kind;
    parsed.stem = name.substr(0, name.size() - suffix_size);
    return std::optional<FrameFileName>(std::move(parsed));
  }
  return std::optional<FrameFileName>();
}

// Reads a rows × cols matrix written one row per line, numbers separated by spaces or tabs.
// Blank lines and '#' lines are skipped; errors name the file and line.
StatusOr<Eigen::MatrixXd> readMatrixText(const fs::path& path, int rows, int cols) {
  OBJDB_ASSIGN_OR_RETURN(const std::string text, internal::readFile(path));
  internal::LineReader lines(text, path.string());
  Eigen::MatrixXd matrix(rows, cols);
  int row = 0;
  absl::string_view line;
  while (lines.next(&line)) {
    if (internal::isCommentOrBlank(line)) continue;
    if (row == rows) {
      return lines.error(
          absl::StrFormat("a %dx%d matrix has only %d rows; found another line", rows, cols, rows));
    }
    const auto fields = internal::splitFields(line);
    if (fields.size() != size_t(cols)) {
      return lines.error(absl::StrFormat("expected %d numbers (row %d of a %dx%d matrix), got %d",
                                         cols, row + 1, rows, cols, fields.size()));
    }
    for (int k = 0; k < cols; ++k) {
      if (!internal::parseDouble(fields[size_t(k)], &matrix(row, k))) {
        return lines.error(absl::StrCat("'", fields[size_t(k)], "' is not a number"));
      }
    }
    ++row;
  }
  OBJDB_RETURN_IF_ERROR(lines.status());
  if (row != rows) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s has %d rows of numbers; expected a %dx%d matrix", path.string(), row, rows, cols));
  }
  return matrix;
}

// camera-intrinsics.txt in `root`, else in its parent folder; empty when neither has one.
fs::path findIntrinsicsFile(const fs::path& root) {
  std::error_code ec;
  if (fs::is_regular_file(root / kIntrinsicsName, ec)) return root / kIntrinsicsName;
  fs::path folder = fs::absolute(root, ec).lexically_normal();
  if (ec) return {};
  if (folder.filename().empty()) folder = folder.parent_path();  // "seq-01/" → "seq-01"
  const fs::path parent_file = folder.parent_path() / kIntrinsicsName;
  if (folder.has_parent_path() && fs::is_regular_file(parent_file, ec)) return parent_file;
  return {};
}

}  // namespace

StatusOr<Intrinsics> readCameraIntrinsicsTxt(const fs::path& path, int width, int height) {
  OBJDB_ASSIGN_OR_RETURN(const Eigen::MatrixXd K, readMatrixText(path, 3, 3));
  if (!K.allFinite()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), ": the camera matrix has a non-finite entry"));
  }
  if (!(K(0, 1) == 0.0 && K(1, 0) == 0.0)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: K[0][1] = %g and K[1][0] = %g must be 0 (expected 'fx 0 cx / 0 fy cy / 0 0 1'; "
        "skew is not supported)",
        path.string(), K(0, 1), K(1, 0)));
  }
  if (!(K(2, 0) == 0.0 && K(2, 1) == 0.0 && K(2, 2) == 1.0)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: last row is (%g %g %g); expected (0 0 1)", path.string(), K(2, 0), K(2, 1), K(2, 2)));
  }
  Intrinsics intrinsics;
  intrinsics.width = width;
  intrinsics.height = height;
  intrinsics.fx = K(0, 0);
  intrinsics.fy = K(1, 1);
  intrinsics.cx = K(0, 2);
  intrinsics.cy = K(1, 2);
  OBJDB_RETURN_IF_ERROR(annotate(intrinsics.validate(), path.string()));
  return intrinsics;
}

StatusOr<Transform> readPoseMatrixFile(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const Eigen::MatrixXd matrix, readMatrixText(path, 4, 4));
  const std::string what = absl::StrCat("pose file ", path.string());
  Transform T;
  T.matrix() = matrix;
  if (matrix.allFinite()) {
    const Eigen::Matrix3d R = T.linear();
    const double ortho_error =
        (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
    if (!(ortho_error <= kPoseMatrixOrthoTolerance)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s has a rotation that is not orthonormal (max |RᵀR − I| = %g > %g); expected a rigid "
          "camera-to-world matrix",
          what, ortho_error, kPoseMatrixOrthoTolerance));
    }
    // Nearest orthonormal matrix; keeps the sign of det(R), so a reflection is still caught below.
    const Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
    T.linear() = svd.matrixU() * svd.matrixV().transpose();
  }
  // Non-finite entries, reflections and a last row other than (0 0 0 1).
  OBJDB_RETURN_IF_ERROR(validateTransform(T, what));
  return T;
}

bool looksLikeSevenScenes(const fs::path& root) {
  std::error_code ec;
  if (fs::exists(root / kIntrinsicsName, ec)) return true;
  for (fs::directory_iterator it(root, ec), end; !ec && it != end; it.increment(ec)) {
    const auto parsed = parseFrameFileName(it->path());
    if (parsed.ok() && parsed->has_value() && (*parsed)->kind == FrameFileKind::kPose) return true;
  }
  return false;
}

StatusOr<std::unique_ptr<SevenScenesDataset>> SevenScenesDataset::open(
    const fs::path& root, const DatasetOptions& options) {
  OBJDB_RETURN_IF_ERROR(internal::checkDirectory(root, "7-Scenes dataset folder"));
  auto dataset = std::unique_ptr<SevenScenesDataset>(new SevenScenesDataset());
  dataset->root_ = root;
  if (options.intrinsics) {
    OBJDB_RETURN_IF_ERROR(annotate(options.intrinsics->validate(), "intrinsics override"));
    dataset->intrinsics_ = *options.intrinsics;
  } else {
    dataset->intrinsics_file_ = findIntrinsicsFile(root);
    if (dataset->intrinsics_file_.empty()) {
      return absl::NotFoundError(
          absl::StrCat("7-Scenes dataset ", root.string(), " has no ", kIntrinsicsName,
                       " (nor has its parent folder); provide the camera intrinsics "
                       "(DatasetOptions::intrinsics)"));
    }
  }

  // Every frame file, by frame number (numeric order, whatever the zero padding).
  struct Found {
    fs::path depth, pose, color;
    std::string stem;
  };
  std::map<uint64_t, Found> found;
  std::error_code ec;
  fs::directory_iterator it(root, ec);
  for (const fs::directory_iterator end; !ec && it != end; it.increment(ec)) {
    std::error_code type_ec;
    if (!it->is_regular_file(type_ec)) continue;
    OBJDB_ASSIGN_OR_RETURN(const auto parsed, parseFrameFileName(it->path()));
    if (!parsed) continue;
    Found& slot = found[parsed->number];
    fs::path* target = nullptr;
    const char* what = "";
    switch (parsed->kind) {
      case FrameFileKind::kDepth:
        target = &slot.depth;
        what = "depth image";
        break;
      case FrameFileKind::kPose:
        target = &slot.pose;
        what = "pose file";
        break;
      case FrameFileKind::kColor:
        target = &slot.color;
        what = "colour image";
        break;
    }
    if (!target->empty()) {
      return absl::InvalidArgumentError(absl::StrFormat("%s and %s are both the %s of frame %d",
                                                        target->string(), it->path().string(), what,
                                                        parsed->number));
    }
    *target = it->path();
    if (slot.stem.empty() || parsed->kind == FrameFileKind::kDepth) slot.stem = parsed->stem;
  }
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat("cannot list 7-Scenes dataset folder ", root.string(), ": ", ec.message()));
  }
  if (found.empty()) {
    return absl::NotFoundError(absl::StrCat(
        "7-Scenes dataset ", root.string(),
        " holds no frame-NNNNNN.depth.png images (a scene whose frames sit in seq-NN/ sub-folders "
        "is opened one sequence folder at a time)"));
  }

  size_t with_color = 0;
  dataset->frames_.reserve(found.size());
  for (const auto& [number, files] : found) {
    if (files.depth.empty()) {
      const fs::path& orphan = files.pose.empty() ? files.color : files.pose;
      return absl::NotFoundError(absl::StrCat(files.pose.empty() ? "colour image " : "pose file ",
                                              orphan.string(), " has no depth image ",
                                              (root / (files.stem + ".depth.png")).string()));
    }
    if (files.pose.empty()) {
      return absl::NotFoundError(absl::StrCat("depth image ", files.depth.string(),
                                              " has no pose file ",
                                              (root / (files.stem + ".pose.txt")).string()));
    }
    FrameFiles frame;
    frame.number = number;
    frame.depth = files.depth;
    frame.color = files.color;
    OBJDB_ASSIGN_OR_RETURN(frame.T_world_camera, readPoseMatrixFile(files.pose));
    with_color += frame.color.empty() ? 0 : 1;
    dataset->frames_.push_back(std::move(frame));
  }
  // Colour is per dataset, as in the objdb layout: a partial set means lost files.
  if (with_color != 0 && with_color != dataset->frames_.size()) {
    for (const FrameFiles& frame : dataset->frames_) {
      if (!frame.color.empty()) continue;
      return absl::NotFoundError(absl::StrFormat(
          "depth image %s has no colour image (.color.png or .color.jpg) but %d of the %d frames "
          "in %s have one; colour must be there for every frame or for none",
          frame.depth.string(), with_color, dataset->frames_.size(), root.string()));
    }
  }
  dataset->has_color_ = with_color != 0;

  if (!options.intrinsics) {
    // The file has no image size: the first depth image defines it, and every frame must match.
    const fs::path& first = dataset->frames_.front().depth;
    OBJDB_ASSIGN_OR_RETURN(const RawDepthImage raw, readUint16Png(first));
    OBJDB_ASSIGN_OR_RETURN(dataset->intrinsics_, readCameraIntrinsicsTxt(dataset->intrinsics_file_,
                                                                         raw.width, raw.height));
  }
  logger("io")->debug(
      "opened 7-Scenes dataset {}: {} frames (numbers {}..{}){}, intrinsics from {}, {}",
      root.string(), dataset->frames_.size(), dataset->frames_.front().number,
      dataset->frames_.back().number, dataset->has_color_ ? ", colour" : "",
      options.intrinsics ? std::string("DatasetOptions") : dataset->intrinsics_file_.string(),
      toString(dataset->intrinsics_));
  return dataset;
}

StatusOr<Frame> SevenScenesDataset::loadFrame(size_t i) const {
  if (!(i < frames_.size())) {
    return absl::OutOfRangeError(absl::StrFormat("frame %d is out of range: %s has %d frames", i,
                                                 root_.string(), frames_.size()));
  }
  const FrameFiles& entry = frames_[i];
  Frame frame;
  frame.index = i;
  frame.timestamp = double(entry.number) / kSevenScenesFrameRateHz;
  frame.T_world_camera = entry.T_world_camera;
  OBJDB_ASSIGN_OR_RETURN(RawDepthImage raw, readUint16Png(entry.depth));
  OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(
      raw.width, raw.height, absl::StrCat("depth image ", entry.depth.string())));
  for (uint16_t& d : raw.data) {
    if (d == kSevenScenesInvalidDepth) d = 0;
  }
  OBJDB_ASSIGN_OR_RETURN(frame.depth, depthFromRaw(raw, kSevenScenesMetresPerUnit));
  if (!entry.color.empty()) {
    OBJDB_ASSIGN_OR_RETURN(ColorImage color, readColorImage(entry.color));
    OBJDB_RETURN_IF_ERROR(intrinsics_.checkImageSize(
        color.width, color.height, absl::StrCat("colour image ", entry.color.string())));
    frame.color = std::move(color);
  }
  return frame;
}

}  // namespace objdb::io
