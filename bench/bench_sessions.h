// Synthetic sessions as wire messages, for the benchmarks that drive a server: one object kind of
// the synthetic library on a floor, seen along the two-box scene's trajectory.
#pragma once

#include <string>
#include <vector>

#include "objdb/v1/objdb.pb.h"
#include "core/common/status.h"

namespace objdb::bench {

// The object kinds of the synthetic library.
const std::vector<std::string>& objectKinds();

// The header of `name` (client_info `client`), then `frames` frames (float depth, RGB8 colour)
// of an object of `kind` on a floor seen by `camera` ("tango", "vga", ...).
StatusOr<std::vector<v1::IngestRequest>> renderSession(const std::string& name,
                                                       const std::string& kind, int frames,
                                                       const std::string& camera,
                                                       const std::string& client);

}  // namespace objdb::bench
