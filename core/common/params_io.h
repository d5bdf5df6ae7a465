// Loading Params from JSON config text or files. Every key is optional (defaults from params.h);
// unknown keys and wrongly typed values are errors naming the key, so a typo never passes
// silently. Example: {"tsdf": {"voxel_size_m": 0.01}, "matching": {"k_nn": 8}}.
#pragma once

#include <filesystem>
#include <string>

#include "core/common/params.h"

namespace objdb {

// Applies the JSON object in `text` on top of `params` and validates the result.
Status applyParamsJson(absl::string_view text, Params* params);
StatusOr<Params> loadParamsFile(const std::filesystem::path& path);
// The full set of parameters as pretty JSON (documentation, `--print-config`).
std::string paramsToJson(const Params& params);

}  // namespace objdb
