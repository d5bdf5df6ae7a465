// Models and grids compared bit for bit, and the definition of a stored model, for tests of the
// ways the database builds and stores one. The definition: the fusion of its raw segments' grids
// in observation order, the union of their voxels, and the model built on that grid at the mean
// known depth of the segments (core/database/object_database_build.cpp builds the same,
// incrementally on merge; this is the independent reference it must equal).
#pragma once

#include <string>

#include "core/common/params.h"
#include "core/common/status.h"
#include "core/database/model_store.h"
#include "core/model/object_model.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::testing {

// `model` rebuilt from its observations' raw segments in `store`, with `params` (as the database
// builds models).
StatusOr<model::ObjectModel> rebuiltFromSegments(const database::ModelStore& store,
                                                 const model::ObjectModel& model,
                                                 const Params& params);

// Field-by-field, bit-exact comparisons; an empty string when equal, else what differs.
// `with_timings`: the build timings too (a model read back from a store; not one built again).
std::string diffModels(const model::ObjectModel& a, const model::ObjectModel& b,
                       bool with_timings = true);
std::string diffLayers(const tsdf::TsdfLayer& a, const tsdf::TsdfLayer& b);

}  // namespace objdb::testing
