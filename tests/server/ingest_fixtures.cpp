#include "tests/server/ingest_fixtures.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <chrono>
#include <thread>

#include "core/sim/generator.h"
#include "core/sim/lounge.h"
#include "core/sim/renderer.h"
#include "core/sim/scene.h"
#include "server/proto_convert.h"

namespace objdb::testing {

void setDeadline(grpc::ClientContext* context) {
  // OBJDB_DEADLINE_SCALE stretches it for instrumented builds (scripts/tsan.sh: ~10× slower).
  static const double scale = [] {
    const char* text = std::getenv("OBJDB_DEADLINE_SCALE");
    const double s = text ? std::atof(text) : 1.0;
    return s >= 1.0 ? std::min(s, 100.0) : 1.0;
  }();
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(int64_t(120000 * scale)));
}

const Recording& twoBoxes() {
  static const Recording recording = [] {
    Recording r;
    const sim::Scene scene = sim::twoBoxesScene("tango", 40);
    auto built = sim::buildScene(scene);
    auto poses = sim::sampleTrajectory(scene.trajectory);
    EXPECT_TRUE(built.ok() && poses.ok());
    const sim::Renderer renderer(scene.intrinsics);
    r.intrinsics = scene.intrinsics;
    for (size_t i = 0; i < poses->size(); ++i) {
      const Frame frame = sim::renderFrame(scene, *built, renderer, (*poses)[i], i, true);
      auto raw = depthToRaw(frame.depth, kMetresPerUnit);
      EXPECT_TRUE(raw.ok());
      r.depth.push_back(*raw);
      r.color.push_back(*frame.color);
      r.poses.push_back(frame.T_world_camera);
    }
    return r;
  }();
  return recording;
}

v1::IngestRequest header(const std::string& name, const Intrinsics& in,
                         const std::string& params_json) {
  v1::IngestRequest request;
  v1::SessionHeader& h = *request.mutable_header();
  h.set_session_name(name);
  h.set_client_info("object_database_service_test");
  h.set_params_json(params_json);
  *h.mutable_intrinsics() = server::toProto(in);
  return request;
}

v1::IngestRequest frame(const Recording& r, size_t k) {
  v1::IngestRequest request;
  v1::Frame& f = *request.mutable_frame();
  f.set_index(k);
  f.set_timestamp_s(double(k) / 30.0);
  *f.mutable_t_world_camera() = server::toProto(r.poses[k]);
  v1::DepthImage& d = *f.mutable_depth();
  d.set_width(uint32_t(r.intrinsics.width));
  d.set_height(uint32_t(r.intrinsics.height));
  d.set_encoding(v1::DepthImage::UINT16);
  d.set_metres_per_unit(kMetresPerUnit);
  std::string bytes(r.depth[k].data.size() * 2, '\0');
  for (size_t i = 0; i < r.depth[k].data.size(); ++i) {
    bytes[2 * i] = char(r.depth[k].data[i] & 0xFF);
    bytes[2 * i + 1] = char(r.depth[k].data[i] >> 8);
  }
  d.set_data(bytes);
  v1::ColorImage& c = *f.mutable_color();
  c.set_width(uint32_t(r.intrinsics.width));
  c.set_height(uint32_t(r.intrinsics.height));
  c.set_encoding(v1::ColorImage::RGB8);
  c.set_data(std::string(reinterpret_cast<const char*>(r.color[k].data.data()),
                         r.color[k].data.size() * 3));
  return request;
}

std::vector<v1::FrameAck> IngestResult::acks() const {
  std::vector<v1::FrameAck> out;
  for (const auto& r : responses) {
    if (r.has_ack()) out.push_back(r.ack());
  }
  return out;
}

::testing::AssertionResult IngestResult::everyFrameAccepted(size_t frames) const {
  if (!status.ok()) return ::testing::AssertionFailure() << "stream: " << status.error_message();
  const std::vector<v1::FrameAck> all = acks();
  if (all.size() != frames) {
    return ::testing::AssertionFailure() << all.size() << " acks for " << frames << " frames";
  }
  for (size_t k = 0; k < frames; ++k) {
    if (all[k].index() != k) {
      return ::testing::AssertionFailure() << "ack " << k << " is for frame " << all[k].index();
    }
    if (!all[k].accepted()) {
      return ::testing::AssertionFailure() << "frame " << k << " rejected: " << all[k].reason();
    }
  }
  return ::testing::AssertionSuccess();
}

size_t IngestResult::count(v1::IngestResponse::EventCase kind) const {
  size_t n = 0;
  for (const auto& r : responses) n += r.event_case() == kind ? 1 : 0;
  return n;
}

IngestResult ingest(v1::ObjectDatabase::Stub& stub, const std::vector<v1::IngestRequest>& requests) {
  grpc::ClientContext context;
  setDeadline(&context);
  auto stream = stub.Ingest(&context);
  IngestResult result;
  std::thread reader([&] {
    v1::IngestResponse response;
    while (stream->Read(&response)) result.responses.push_back(response);
  });
  for (const auto& r : requests) {
    if (!stream->Write(r)) break;
  }
  stream->WritesDone();
  reader.join();
  result.status = stream->Finish();
  return result;
}

std::vector<v1::IngestRequest> session(const std::string& name, size_t frames) {
  const Recording& r = twoBoxes();
  std::vector<v1::IngestRequest> requests = {header(name, r.intrinsics)};
  for (size_t k = 0; k < frames; ++k) requests.push_back(frame(r, k));
  return requests;
}

grpc::Status endSession(v1::ObjectDatabase::Stub& stub, const std::string& name,
                        v1::EndSessionResponse* response) {
  grpc::ClientContext context;
  setDeadline(&context);
  v1::EndSessionRequest request;
  request.set_session_name(name);
  return stub.EndSession(&context, request, response);
}

std::string listeningAddress(const std::string& log) {
  const std::string prefix = "listening on 127.0.0.1:";
  const size_t at = log.find(prefix);
  if (at == std::string::npos) return "";
  size_t end = at + prefix.size();
  while (end < log.size() && std::isdigit(static_cast<unsigned char>(log[end]))) ++end;
  const size_t start = at + std::string("listening on ").size();
  return log.substr(start, end - start);
}

}  // namespace objdb::testing
