// Conversions between objdb's core types and the public API's messages (proto/objdb/v1): poses,
// intrinsics, the wire encodings of depth and colour images (validated, with per-pixel counts),
// meshes and clouds (a large mesh is cut into independent chunks), stored sessions and models.
// Every error names the field at fault and its value, as the API promises.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/mesh.h"
#include "core/common/status.h"
#include "core/common/transform.h"
#include "core/database/object_database.h"
#include "objdb/v1/objdb.pb.h"
#include "storage/store.h"

namespace objdb::server {

void setVector(const Eigen::Vector3d& v, v1::Vector3* out);
v1::Pose toProto(const Transform& T);
// INVALID_ARGUMENT naming `field` for non-finite values or a quaternion off unit norm.
StatusOr<Transform> fromProto(const v1::Pose& pose, const std::string& field);

v1::Intrinsics toProto(const Intrinsics& intrinsics);
StatusOr<Intrinsics> fromProto(const v1::Intrinsics& intrinsics, const std::string& field);
// Intrinsics as storage keeps them (storage::intrinsicsJson); an unreadable text gives empty
// intrinsics.
v1::Intrinsics intrinsicsFromJson(const std::string& json);

// Per-frame pixel counts of a decoded depth image (FrameCounters).
struct DepthCounts {
  uint32_t missing = 0;  // 0, or NaN for FLOAT32
  uint32_t invalid = 0;  // negative or infinite FLOAT32 samples (set to "no measurement")
};

// Depth in metres from its wire encoding; its size must be the intrinsics' image size.
StatusOr<DepthImage> decodeDepth(const v1::DepthImage& depth, const Intrinsics& intrinsics,
                                 DepthCounts* counts);
// Colour from its wire encoding; its size must be width × height.
StatusOr<ColorImage> decodeColor(const v1::ColorImage& color, int width, int height);

// Wire encodings a client sends: FLOAT32 depth (metres, exact) and RGB8 colour.
v1::DepthImage encodeDepth(const DepthImage& depth);
v1::ColorImage encodeColor(const ColorImage& color);

void toProto(const TriangleMesh& mesh, v1::Mesh* out);
// What a client receives, back in core types (attributes of the wrong length are dropped).
TriangleMesh meshFromProto(const v1::Mesh& mesh);
PointCloud cloudFromProto(const v1::PointCloud& cloud);
void toProto(const PointCloud& cloud, v1::PointCloud* out);
// The mesh cut into independent sub-meshes of at most about `max_bytes` each once serialised
// (triangles in order; each chunk carries the vertices its triangles use). An empty mesh gives
// no chunks.
std::vector<TriangleMesh> splitMesh(const TriangleMesh& mesh, size_t max_bytes);

// "2026-11-30T08:38:14Z" (storage's timestamps) as seconds since the Unix epoch; 0 when empty or
// unreadable.
double unixSeconds(const std::string& iso8601_utc);
v1::SessionState toProto(storage::SessionState state);
// The summary of a stored model (ListObjects, GetObject).
void toProto(const storage::ModelSummary& model, v1::ObjectSummary* out);

// A merge's evidence (the accepted candidate's numbers).
void toProto(const database::CandidateResult& merge, v1::MergeEvidence* out);
// REMOVED: object `removed` is gone; the segment is in `now_in` (0: none).
v1::ObjectEvent removedEvent(int64_t removed, int64_t now_in, uint64_t segment_id);
// What one insert did to the objects, as Ingest announces it: CREATED (a new object) or MERGED
// (into an object); REMOVED when the segment's earlier version emptied its old object; then one
// MERGED per existing object that joined the surviving one. An unusable segment: only REMOVED.
std::vector<v1::ObjectEvent> objectEvents(const database::InsertReport& report,
                                          uint64_t segment_id);

// A session's counters as the store keeps them (storage::SessionInfo::counters_json): JSON with
// the proto field names. countersFromJson: false when `json` is empty or not such a JSON.
std::string countersJson(const v1::SessionCounters& counters);
bool countersFromJson(const std::string& json, v1::SessionCounters* counters);

}  // namespace objdb::server
