#include "client/cli_util.h"

#include "core/common/params_io.h"

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>

namespace objdb::cli {

bool isDatasetDir(const std::filesystem::path& path) {
  std::error_code ec;
  return std::filesystem::exists(path / "poses.txt", ec) ||
         std::filesystem::exists(path / "depth.txt", ec);
}

std::vector<std::filesystem::path> datasetSubfolders(const std::filesystem::path& root) {
  std::vector<std::filesystem::path> folders;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(root, ec)) {
    if (entry.is_directory() && isDatasetDir(entry.path())) folders.push_back(entry.path());
  }
  std::sort(folders.begin(), folders.end());
  return folders;
}

StatusOr<std::vector<std::pair<std::string, std::filesystem::path>>> datasetSessions(
    const std::vector<std::string>& paths) {
  namespace fs = std::filesystem;
  std::vector<std::pair<std::string, fs::path>> out;
  for (const auto& arg : paths) {
    const fs::path p = fs::path(arg).lexically_normal();
    if (isDatasetDir(p)) {
      out.emplace_back(p.filename().string(), p);
      continue;
    }
    std::error_code ec;
    if (!fs::is_directory(p, ec)) {
      return absl::NotFoundError(absl::StrFormat("%s is not a dataset folder", arg));
    }
    const std::vector<fs::path> children = datasetSubfolders(p);
    if (children.empty()) {
      return absl::NotFoundError(absl::StrFormat(
          "%s holds no dataset (no poses.txt or depth.txt in it or its subfolders)", arg));
    }
    for (const auto& c : children) out.emplace_back(c.filename().string(), c);
  }
  return out;
}

std::string counted(uint64_t n, const std::string& noun, const std::string& plural) {
  return absl::StrCat(n, " ", n == 1 ? noun : plural.empty() ? noun + "s" : plural);
}

bool parseInt(const char* text, long long lo, long long hi, long long* out) {
  char* end = nullptr;
  errno = 0;
  const long long v = std::strtoll(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || v < lo || v > hi) return false;
  *out = v;
  return true;
}

int usageError(const char* command, const std::string& message, const char* usage) {
  std::fprintf(stderr, "objdb %s: %s\n\n%s", command, message.c_str(), usage);
  return 2;
}

int reportError(const char* command, const Status& status) {
  std::fprintf(stderr, "objdb %s: %s\n", command, std::string(status.message()).c_str());
  return 1;
}

bool parseDatasetJobOption(const std::string& name, const char* value, DatasetJobOptions* options,
                           std::string* error) {
  error->clear();
  if (name == "--dataset") {
    options->dataset = value;
  } else if (name == "--out") {
    options->out = value;
  } else if (name == "--config") {
    options->config = value;
  } else if (name == "--every") {
    if (!parseInt(value, 1, 1000000, &options->every)) *error = "--every needs an integer >= 1";
  } else if (name == "--threads") {
    if (!parseInt(value, 1, 64, &options->threads)) *error = "--threads needs an integer 1..64";
  } else {
    return false;
  }
  return true;
}

StatusOr<Params> loadParams(const std::string& path) {
  if (path.empty()) return Params();
  return loadParamsFile(path);
}

}  // namespace objdb::cli
