// Loopback clients of objdb.v1.ObjectDatabase for the server tests: a recorded two-box session
// (Tango depth in millimetres and colour), the wire messages of its header and frames, a whole
// Ingest stream written and read, and EndSession.
#pragma once

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/transform.h"
#include "objdb/v1/objdb.grpc.pb.h"

namespace objdb::testing {

inline constexpr double kMetresPerUnit = 0.001;  // the recording's depth unit

// A deadline generous enough for any call of these tests (2 minutes, times the environment's
// OBJDB_DEADLINE_SCALE when that is above 1).
void setDeadline(grpc::ClientContext* context);

struct Recording {
  Intrinsics intrinsics;
  std::vector<RawDepthImage> depth;
  std::vector<ColorImage> color;
  std::vector<Transform> poses;
};

// Two boxes on a floor seen by the Tango camera, 40 frames, rendered once.
const Recording& twoBoxes();

v1::IngestRequest header(const std::string& name, const Intrinsics& intrinsics,
                         const std::string& params_json = "");
// Frame k of the recording: UINT16 depth (little-endian millimetres) and RGB8 colour.
v1::IngestRequest frame(const Recording& r, size_t k);
// The header of `name`, then the first `frames` frames of twoBoxes().
std::vector<v1::IngestRequest> session(const std::string& name, size_t frames);

struct IngestResult {
  grpc::Status status;
  std::vector<v1::IngestResponse> responses;
  std::vector<v1::FrameAck> acks() const;
  size_t count(v1::IngestResponse::EventCase kind) const;
  // Success when the stream ended OK with one ack per frame, for frames 0 .. frames − 1 in order,
  // all accepted; else what differs first.
  ::testing::AssertionResult everyFrameAccepted(size_t frames) const;
};

// Writes `requests`, half-closes, reads every response (on a second thread, so that the
// server's backpressure cannot stall the writer) and returns the stream's status.
IngestResult ingest(v1::ObjectDatabase::Stub& stub, const std::vector<v1::IngestRequest>& requests);

grpc::Status endSession(v1::ObjectDatabase::Stub& stub, const std::string& name,
                        v1::EndSessionResponse* response);

// The address in objdb-server's "listening on 127.0.0.1:43121" log line, or "" if absent.
std::string listeningAddress(const std::string& log);

}  // namespace objdb::testing
