// One row of the merge sheet (`objdb report merges`; `objdb web`'s object page): a model's
// evidence (surface kind, extent, each merge's e_ICP, e_TSDF, o_TSDF and scene checks), its
// surface cloud, and up to five of its placements drawn over the camera image of the frame that
// sees each best (db_scan.h's scan), the rest of the image dimmed.
#pragma once

#include <map>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "client/db_scan.h"
#include "core/common/status.h"
#include "core/io/dataset.h"

namespace objdb::cli {

inline constexpr int kSheetRowHeight = 240, kTileWidth = 320, kInfoWidth = 380,
                     kCloudWidth = 240, kMaxTiles = 5;
inline constexpr int kSheetWidth = kInfoWidth + kCloudWidth + kMaxTiles * kTileWidth;

// A line of light text at (x, y) (its baseline's left end), as the sheet writes it.
void sheetText(cv::Mat* image, const std::string& line, int x, int y, double scale = 0.45,
               const cv::Scalar& colour = cv::Scalar(235, 235, 235));

// Draws `row` (scanned: scanFrames) into `out`, a kSheetRowHeight x kSheetWidth BGR image;
// `opened` holds the datasets of the sessions (a placement in another session says so). Errors:
// a frame that cannot be read.
Status drawSheetRow(const Row& row,
                    const std::map<std::string, std::unique_ptr<io::Dataset>>& opened,
                    cv::Mat* out);

}  // namespace objdb::cli
