#include "core/database/merge_source.h"

#include <charconv>

#include "absl/strings/str_format.h"

namespace objdb::database {
namespace {

constexpr std::string_view kSegment = "segment ", kModel = "model ";

// The whole of `text` as a decimal number.
template <typename Int>
bool wholeNumber(std::string_view text, Int* out) {
  const char* end = text.data() + text.size();
  const auto [at, error] = std::from_chars(text.data(), end, *out);
  return !text.empty() && error == std::errc() && at == end;
}

}  // namespace

std::string segmentSource(const std::string& session, gsm::Label label) {
  return absl::StrFormat("%s%s/%d", kSegment, session, label);
}

std::string modelSource(int64_t id) { return absl::StrFormat("%s%d", kModel, id); }

bool parseSegmentSource(std::string_view source, std::string* session, gsm::Label* label) {
  if (source.substr(0, kSegment.size()) != kSegment) return false;
  const std::string_view rest = source.substr(kSegment.size());
  const size_t slash = rest.rfind('/');
  if (slash == std::string_view::npos || slash == 0) return false;
  *session = std::string(rest.substr(0, slash));
  return wholeNumber(rest.substr(slash + 1), label);
}

bool parseModelSource(std::string_view source, int64_t* id) {
  return source.substr(0, kModel.size()) == kModel &&
         wholeNumber(source.substr(kModel.size()), id) && *id > 0;
}

}  // namespace objdb::database
