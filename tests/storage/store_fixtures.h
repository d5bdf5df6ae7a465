// Synthetic object models and raw segments for the storage tests: every field filled with
// seed-dependent values so that a round trip can be compared bit for bit, and a consistency rule
// (cloud size, keypoints, descriptors and observations all follow the observation count) that a
// reader can check to see whether it got a whole model.
#pragma once

#include <cstdint>
#include <string>

#include "core/database/model_store.h"
#include "core/model/object_model.h"
#include "tests/support/model_compare.h"  // diffModels, diffLayers

namespace objdb::testing {

// A model with `observations` observations (sessions "s0", "s1", ...), a small TSDF grid (two
// blocks), a cloud of 10·observations points with normals and colours, 3·observations keypoints
// with descriptors.
model::ObjectModel makeStoreModel(uint32_t seed, int observations);
// Whether `m` satisfies the rule above (a reader saw a whole model).
bool wholeModel(const model::ObjectModel& m);

database::RawSegmentRecord makeRawSegment(const std::string& session, uint32_t label, uint32_t seed);

}  // namespace objdb::testing
