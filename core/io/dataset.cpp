#include "core/io/dataset.h"

#include "core/io/io_util.h"
#include "core/io/objdb_dataset.h"
#include "core/io/seven_scenes_dataset.h"
#include "core/io/tum_dataset.h"

namespace objdb::io {

StatusOr<std::unique_ptr<Dataset>> openDataset(const std::filesystem::path& root,
                                               const DatasetOptions& options) {
  OBJDB_RETURN_IF_ERROR(internal::checkDirectory(root, "dataset folder"));
  std::error_code ec;
  if (std::filesystem::exists(root / "poses.txt", ec)) {
    OBJDB_ASSIGN_OR_RETURN(auto dataset, ObjdbDataset::open(root, options));
    return std::unique_ptr<Dataset>(std::move(dataset));
  }
  if (std::filesystem::exists(root / "depth.txt", ec)) {
    OBJDB_ASSIGN_OR_RETURN(auto dataset, TumDataset::open(root, options));
    return std::unique_ptr<Dataset>(std::move(dataset));
  }
  if (looksLikeSevenScenes(root)) {
    OBJDB_ASSIGN_OR_RETURN(auto dataset, SevenScenesDataset::open(root, options));
    return std::unique_ptr<Dataset>(std::move(dataset));
  }
  return absl::InvalidArgumentError(absl::StrCat(
      "dataset folder ", root.string(),
      " is in none of the known layouts: not an objdb dataset (no poses.txt), not a TUM RGB-D "
      "sequence (no depth.txt), not a 7-Scenes / 3DMatch sequence (no camera-intrinsics.txt or "
      "frame-NNNNNN.pose.txt)"));
}

}  // namespace objdb::io
