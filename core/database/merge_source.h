// MergeRecord::source, what a merge took in, written and read in one place: "segment
// <session>/<label>" (a raw segment inserted) or "model <id>" (a stored model that joined).
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "core/gsm/label_voxel.h"

namespace objdb::database {

std::string segmentSource(const std::string& session, gsm::Label label);
std::string modelSource(int64_t id);
// The segment of a "segment ..." source; false for anything else.
bool parseSegmentSource(std::string_view source, std::string* session, gsm::Label* label);
// The model of a "model ..." source; false for anything else.
bool parseModelSource(std::string_view source, int64_t* id);

}  // namespace objdb::database
