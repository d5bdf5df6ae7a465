#include "core/io/io_util.h"

#include <charconv>
#include <cmath>
#include <fstream>
#include <new>
#include <system_error>

#include <nlohmann/json.hpp>

namespace objdb::io::internal {
namespace fs = std::filesystem;
using nlohmann::json;

StatusOr<std::string> readFile(const fs::path& path) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (!fs::exists(status)) {
    return absl::NotFoundError(absl::StrCat(path.string(), " does not exist"));
  }
  if (!fs::is_regular_file(status)) {
    return absl::InvalidArgumentError(absl::StrCat(path.string(), " is not a regular file"));
  }
  const uint64_t size = fs::file_size(path, ec);
  if (ec) {
    return absl::UnavailableError(
        absl::StrCat("cannot read the size of ", path.string(), ": ", ec.message()));
  }
  if (!(size <= kMaxFileBytes)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s is %d bytes; the limit is %d", path.string(), size, kMaxFileBytes));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::UnavailableError(absl::StrCat("cannot open ", path.string()));
  std::string data;
  try {
    data.resize(size);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(
        absl::StrFormat("not enough memory to read %s (%d bytes)", path.string(), size));
  }
  in.read(data.data(), static_cast<std::streamsize>(size));
  if (static_cast<uint64_t>(in.gcount()) != size) {
    return absl::DataLossError(
        absl::StrFormat("%s: read %d of %d bytes", path.string(), in.gcount(), size));
  }
  return data;
}

Status writeFileAtomic(const fs::path& path, absl::string_view data) {
  std::error_code ec;
  if (path.has_parent_path() && !fs::is_directory(path.parent_path(), ec)) {
    return absl::NotFoundError(absl::StrCat("cannot write ", path.string(), ": folder ",
                                            path.parent_path().string(), " does not exist"));
  }
  fs::path tmp = path;
  tmp += ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) return absl::UnavailableError(absl::StrCat("cannot create ", tmp.string()));
    out.write(data.data(), static_cast<std::streamsize>(data.size()));
    out.flush();
    if (!out) {
      out.close();
      fs::remove(tmp, ec);
      return absl::UnavailableError(absl::StrCat("cannot write ", tmp.string()));
    }
  }
  fs::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    fs::remove(tmp, ignored);
    return absl::UnavailableError(
        absl::StrCat("cannot rename ", tmp.string(), " to ", path.string(), ": ", ec.message()));
  }
  return absl::OkStatus();
}

Status checkDirectory(const fs::path& path, absl::string_view what) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (!fs::exists(status)) {
    return absl::NotFoundError(absl::StrCat(what, " ", path.string(), " does not exist"));
  }
  if (!fs::is_directory(status)) {
    return absl::InvalidArgumentError(absl::StrCat(what, " ", path.string(), " is not a folder"));
  }
  return absl::OkStatus();
}

bool parseDouble(absl::string_view token, double* value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty() || token.front() == '+') return false;
  const char* end = token.data() + token.size();
  const auto result = std::from_chars(token.data(), end, *value);
  return result.ec == std::errc() && result.ptr == end;
}

bool parseInt64(absl::string_view token, int64_t* value) {
  if (!token.empty() && token.front() == '+') token.remove_prefix(1);
  if (token.empty() || token.front() == '+') return false;
  const char* end = token.data() + token.size();
  const auto result = std::from_chars(token.data(), end, *value);
  return result.ec == std::errc() && result.ptr == end;
}

bool parseUint64(absl::string_view token, uint64_t* value) {
  if (token.empty() || token.front() == '-' || token.front() == '+') return false;
  const char* end = token.data() + token.size();
  const auto result = std::from_chars(token.data(), end, *value);
  return result.ec == std::errc() && result.ptr == end;
}

std::string formatDouble(double value) {
  char buffer[64];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

std::string toLower(absl::string_view text) {
  std::string out(text);
  for (char& c : out) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return out;
}

bool LineReader::next(absl::string_view* line) {
  if (!status_.ok() || pos_ >= text_.size()) return false;
  size_t end = text_.find('\n', pos_);
  if (end == absl::string_view::npos) end = text_.size();
  ++line_number_;
  if (end - pos_ > kMaxLineBytes) {
    status_ = error(absl::StrFormat("line is longer than %d bytes", kMaxLineBytes));
    return false;
  }
  *line = text_.substr(pos_, end - pos_);
  if (!line->empty() && line->back() == '\r') line->remove_suffix(1);
  pos_ = end + 1;
  return true;
}

Status LineReader::error(absl::string_view message) const {
  return absl::InvalidArgumentError(
      absl::StrCat(file_name_, " line ", line_number_, ": ", message));
}

std::vector<absl::string_view> splitFields(absl::string_view line) {
  std::vector<absl::string_view> fields;
  size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t')) ++i;
    const size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t') ++i;
    if (i > start) fields.push_back(line.substr(start, i - start));
  }
  return fields;
}

bool isCommentOrBlank(absl::string_view line) {
  for (char c : line) {
    if (c == ' ' || c == '\t') continue;
    return c == '#';
  }
  return true;
}

StatusOr<json> readJsonFile(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string text, readFile(path));
  try {
    return json::parse(text);
  } catch (const json::exception& e) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), " is not valid JSON: ", e.what()));
  }
}

Status writeJsonFile(const fs::path& path, const nlohmann::ordered_json& value) {
  std::string text;
  try {
    text = value.dump(2);
  } catch (const nlohmann::json::exception& e) {
    return absl::InvalidArgumentError(
        absl::StrCat("cannot serialise ", path.string(), ": ", e.what()));
  }
  text += '\n';
  return writeFileAtomic(path, text);
}

namespace {

Status readJsonInt(const json& object, const std::string& key, const fs::path& path, int* out) {
  const auto it = object.find(key);
  if (it == object.end()) {
    return absl::InvalidArgumentError(absl::StrCat(path.string(), ": missing key '", key, "'"));
  }
  if (!it->is_number_integer()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), ": key '", key, "' must be an integer (got ", it->dump(), ")"));
  }
  const int64_t v = it->get<int64_t>();
  if (!(v >= 0 && v <= kMaxImageSide)) {
    return absl::InvalidArgumentError(absl::StrFormat("%s: key '%s' = %d is outside 0..%d",
                                                      path.string(), key, v, kMaxImageSide));
  }
  *out = static_cast<int>(v);
  return absl::OkStatus();
}

Status readJsonDouble(const json& object, const std::string& key, const fs::path& path,
                      double* out) {
  const auto it = object.find(key);
  if (it == object.end()) {
    return absl::InvalidArgumentError(absl::StrCat(path.string(), ": missing key '", key, "'"));
  }
  if (!it->is_number()) {
    return absl::InvalidArgumentError(
        absl::StrCat(path.string(), ": key '", key, "' must be a number (got ", it->dump(), ")"));
  }
  *out = it->get<double>();
  return absl::OkStatus();
}

}  // namespace

StatusOr<IntrinsicsFile> readIntrinsicsFile(const fs::path& path, absl::string_view scale_key) {
  OBJDB_ASSIGN_OR_RETURN(const json root, readJsonFile(path));
  if (!root.is_object()) {
    return absl::InvalidArgumentError(absl::StrCat(path.string(), " must hold a JSON object"));
  }
  const std::string scale(scale_key);
  for (const auto& [key, value] : root.items()) {
    const bool known = key == "width" || key == "height" || key == "fx" || key == "fy" ||
                       key == "cx" || key == "cy" || key == scale;
    if (!known && !value.is_string()) {
      return absl::InvalidArgumentError(absl::StrCat(path.string(), ": unknown key '", key,
                                                     "' (known: width, height, fx, fy, cx, cy, ",
                                                     scale, "; other keys may only hold text)"));
    }
  }
  IntrinsicsFile file;
  Intrinsics& k = file.intrinsics;
  OBJDB_RETURN_IF_ERROR(readJsonInt(root, "width", path, &k.width));
  OBJDB_RETURN_IF_ERROR(readJsonInt(root, "height", path, &k.height));
  OBJDB_RETURN_IF_ERROR(readJsonDouble(root, "fx", path, &k.fx));
  OBJDB_RETURN_IF_ERROR(readJsonDouble(root, "fy", path, &k.fy));
  OBJDB_RETURN_IF_ERROR(readJsonDouble(root, "cx", path, &k.cx));
  OBJDB_RETURN_IF_ERROR(readJsonDouble(root, "cy", path, &k.cy));
  OBJDB_RETURN_IF_ERROR(annotate(k.validate(), path.string()));
  if (root.contains(scale)) {
    double value = 0.0;
    OBJDB_RETURN_IF_ERROR(readJsonDouble(root, scale, path, &value));
    if (!(std::isfinite(value) && value > 0.0)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s: key '%s' must be finite and > 0 (got %g)", path.string(), scale, value));
    }
    file.depth_scale = value;
  }
  return file;
}

Status writeIntrinsicsFile(const fs::path& path, const Intrinsics& intrinsics,
                           absl::string_view scale_key, double scale) {
  OBJDB_RETURN_IF_ERROR(annotate(intrinsics.validate(), absl::StrCat("writing ", path.string())));
  if (!(std::isfinite(scale) && scale > 0.0)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "writing %s: %s must be finite and > 0 (got %g)", path.string(), scale_key, scale));
  }
  nlohmann::ordered_json root = nlohmann::ordered_json::object();
  root["width"] = intrinsics.width;
  root["height"] = intrinsics.height;
  root["fx"] = intrinsics.fx;
  root["fy"] = intrinsics.fy;
  root["cx"] = intrinsics.cx;
  root["cy"] = intrinsics.cy;
  root[std::string(scale_key)] = scale;
  return writeJsonFile(path, root);
}

}  // namespace objdb::io::internal
