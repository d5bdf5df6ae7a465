// Shared helpers of the objdb subcommands: strict integer options and uniform error output
// ("objdb <command>: message"; usage errors exit 2, runtime errors exit 1).
#pragma once

#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "core/common/params.h"
#include "core/common/status.h"

namespace objdb::cli {

// A dataset folder (objdb or TUM layout): it holds poses.txt or depth.txt.
bool isDatasetDir(const std::filesystem::path& path);
// The dataset folders directly inside `root` (a folder of sessions), in name order.
std::vector<std::filesystem::path> datasetSubfolders(const std::filesystem::path& root);

// The sessions named by command-line paths, as (name, folder) in order: a dataset folder is one
// session named after it; a folder of dataset folders gives each of them, in name order.
// NOT_FOUND for a path that is neither.
StatusOr<std::vector<std::pair<std::string, std::filesystem::path>>> datasetSessions(
    const std::vector<std::string>& paths);

// "1 pose", "3 poses": `n` and the noun, plural unless n is 1 (`plural` empty: noun + "s").
std::string counted(uint64_t n, const std::string& noun, const std::string& plural = "");

// Parses a whole decimal integer within [lo, hi]; false on anything else.
bool parseInt(const char* text, long long lo, long long hi, long long* out);

// Prints "objdb <command>: <message>", a blank line and `usage` to stderr; returns 2.
int usageError(const char* command, const std::string& message, const char* usage);

// Prints "objdb <command>: <status message>" to stderr; returns 1.
int reportError(const char* command, const Status& status);

// Options of the commands that run over a whole dataset (fuse, gsm).
struct DatasetJobOptions {
  std::string dataset;  // --dataset DIR
  std::string out;      // --out FILE
  std::string config;   // --config FILE (JSON parameters)
  long long every = 1;  // --every N: use every N-th frame
  long long threads = 2;  // --threads N
};

// Takes `name value` if it is one of the options above: true when taken, with `*error` set when
// the value is bad; false when the option is not one of them.
bool parseDatasetJobOption(const std::string& name, const char* value, DatasetJobOptions* options,
                           std::string* error);

// The parameters of a `--config` file, or the defaults when `path` is empty.
StatusOr<Params> loadParams(const std::string& path);

}  // namespace objdb::cli
