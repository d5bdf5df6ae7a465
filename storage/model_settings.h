// One database file, one way of describing models. The model, keypoint and descriptor parameters,
// the voxel size and the mesh weight decide what a stored model's cloud, keypoints and FPFH
// descriptors are; models described differently do not match each other (an FPFH over a 2 cm
// surface is not comparable with one over the 1 cm cloud), so adding sessions with other
// settings would silently stop repeated objects from merging. Sessions store their effective parameters (SessionInfo::
// params_json); this check compares them with the parameters of a new session.
#pragma once

#include <vector>

#include "core/common/params.h"
#include "core/common/status.h"
#include "storage/store.h"

namespace objdb::storage {

// OK when `params` describe models as the newest stored session that recorded its parameters
// did (sessions whose params_json holds no "descriptors" section, e.g. from files written before
// this check, are not compared; no such session: OK). Otherwise FAILED_PRECONDITION naming the
// first differing key, both values and that session. A key that session did not record (one a
// later version added) counts as a difference: its default may describe models differently.
Status checkModelSettings(const std::vector<SessionInfo>& stored, const Params& params);

}  // namespace objdb::storage
