#include "bench/bench_sessions.h"

#include "core/sim/generator.h"
#include "core/sim/lounge.h"
#include "core/sim/renderer.h"
#include "core/sim/scene.h"
#include "server/proto_convert.h"

namespace objdb::bench {

const std::vector<std::string>& objectKinds() {
  static const std::vector<std::string> k = {"cow",        "cube_chair",   "fire_extinguisher",
                                             "gas_cylinder", "helmet",     "large_box",
                                             "round_chair", "round_table", "small_container",
                                             "square_table"};
  return k;
}

StatusOr<std::vector<v1::IngestRequest>> renderSession(const std::string& name,
                                                       const std::string& kind, int frames,
                                                       const std::string& camera,
                                                       const std::string& client) {
  sim::Scene scene = sim::twoBoxesScene(camera, frames);
  scene.name = name;
  // Keep the floor, replace the two boxes by one object of `kind`.
  std::erase_if(scene.objects, [](const sim::SceneObject& o) { return !o.structure; });
  sim::SceneObject object;
  object.id = 1;
  object.category = kind;
  object.mesh = kind;
  object.albedo = Rgb8{150, 120, 90};
  scene.objects.push_back(object);
  OBJDB_ASSIGN_OR_RETURN(const auto built, sim::buildScene(scene));
  OBJDB_ASSIGN_OR_RETURN(const auto poses, sim::sampleTrajectory(scene.trajectory));
  const sim::Renderer renderer(scene.intrinsics);
  std::vector<v1::IngestRequest> requests(1);
  v1::SessionHeader& h = *requests[0].mutable_header();
  h.set_session_name(name);
  h.set_client_info(client);
  *h.mutable_intrinsics() = server::toProto(scene.intrinsics);
  for (size_t i = 0; i < poses.size(); ++i) {
    const Frame frame = sim::renderFrame(scene, built, renderer, poses[i], i, true);
    v1::IngestRequest request;
    v1::Frame& f = *request.mutable_frame();
    f.set_index(i);
    f.set_timestamp_s(frame.timestamp);
    *f.mutable_t_world_camera() = server::toProto(frame.T_world_camera);
    *f.mutable_depth() = server::encodeDepth(frame.depth);
    *f.mutable_color() = server::encodeColor(*frame.color);
    requests.push_back(std::move(request));
  }
  return requests;
}

}  // namespace objdb::bench
