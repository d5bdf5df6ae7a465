// Private helpers of core/io: whole-file reads, atomic writes, strict number parsing and
// formatting, line splitting with line numbers, and the intrinsics.json reader shared by the
// objdb and TUM layouts. Not part of the module's API.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "absl/strings/string_view.h"
#include "core/common/intrinsics.h"
#include "core/common/status.h"

namespace objdb::io::internal {

// Files larger than this are refused before reading (meshes and lists; images go to OpenCV).
inline constexpr uint64_t kMaxFileBytes = uint64_t{4} << 30;
// Text lines longer than this are an error (no legitimate list or mesh line comes close).
inline constexpr size_t kMaxLineBytes = size_t{1} << 20;

// Reads the whole file; NotFound when it does not exist, names the file in every error.
StatusOr<std::string> readFile(const std::filesystem::path& path);
// Writes `data` to a temporary file beside `path` and renames it over `path`, so a reader never
// sees a half-written file.
Status writeFileAtomic(const std::filesystem::path& path, absl::string_view data);
// Fails unless `path` is an existing directory; `what` says what the folder is for.
Status checkDirectory(const std::filesystem::path& path, absl::string_view what);

// Strict parsing of a whole token (no trailing characters). Accepts "nan"/"inf" for doubles;
// callers check finiteness themselves.
bool parseDouble(absl::string_view token, double* value);
bool parseInt64(absl::string_view token, int64_t* value);
bool parseUint64(absl::string_view token, uint64_t* value);

// Shortest text that reads back as exactly the same double.
std::string formatDouble(double value);

// Lowercase ASCII copy.
std::string toLower(absl::string_view text);

// Iterates over the lines of a text buffer ('\n' or "\r\n"), counting from 1.
class LineReader {
 public:
  LineReader(absl::string_view text, std::string file_name)
      : text_(text), file_name_(std::move(file_name)) {}
  // Returns false at the end of the text. A line longer than kMaxLineBytes sets `status()`.
  bool next(absl::string_view* line);
  size_t lineNumber() const { return line_number_; }
  const Status& status() const { return status_; }
  // "file.txt line 12: <message>" as InvalidArgument.
  Status error(absl::string_view message) const;
  size_t offset() const { return pos_; }

 private:
  absl::string_view text_;
  std::string file_name_;
  size_t pos_ = 0;
  size_t line_number_ = 0;
  Status status_;
};

// Splits on spaces and tabs, dropping empty fields.
std::vector<absl::string_view> splitFields(absl::string_view line);
// True for a blank line or one whose first non-blank character is '#'.
bool isCommentOrBlank(absl::string_view line);

// JSON files: parse errors name the file and nlohmann's line/column.
StatusOr<nlohmann::json> readJsonFile(const std::filesystem::path& path);
Status writeJsonFile(const std::filesystem::path& path, const nlohmann::ordered_json& json);

// intrinsics.json: width, height, fx, fy, cx, cy and an optional depth-scale key (`scale_key`:
// "depth_scale_m" for objdb, "depth_factor" for TUM). Other keys are accepted only when their
// value is a string (notes such as "source"); an unknown number, bool, array or object is an
// error naming the key, so a mistyped parameter never falls back to a default.
struct IntrinsicsFile {
  Intrinsics intrinsics;
  std::optional<double> depth_scale;  // value of `scale_key` when present
};
StatusOr<IntrinsicsFile> readIntrinsicsFile(const std::filesystem::path& path,
                                            absl::string_view scale_key);
Status writeIntrinsicsFile(const std::filesystem::path& path, const Intrinsics& intrinsics,
                           absl::string_view scale_key, double scale);

}  // namespace objdb::io::internal
