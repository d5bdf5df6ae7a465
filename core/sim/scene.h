// Scene description of the synthetic world: object instances (procedural library kinds or mesh
// files) with poses and albedo, a camera (intrinsics), a noise model and a keyframed camera
// trajectory. Read from / written to JSON scene files (docs/synthetic-world.md):
//   {"name": "...", "camera": "tango" | {"width":..,"height":..,"fx":..,"fy":..,"cx":..,"cy":..},
//    "depth_scale_m": 0.001, "noise": {"enabled": true, "seed": 1, ...},
//    "drift": {"translation_m": 0.025, "rotation_deg": 0.4, "seed": 1},   (optional)
//    "objects": [{"id": 1, "category": "cow", "mesh": "cow" | "file:meshes/x.obj",
//                 "scale": [1,1,1], "size": [7,5] | [0.6], "albedo": [r,g,b], "structure": false,
//                 "pose": {"t": [x,y,z], "yaw_deg": 30} | {"t": [...], "q": [qx,qy,qz,qw]}}],
//    "trajectory": {"frames": 300, "fps": 30, "closed": false,
//                   "keyframes": [{"position": [x,y,z], "look_at": [x,y,z]}, ...]}}
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "core/common/image.h"
#include "core/common/intrinsics.h"
#include "core/common/mesh.h"
#include "core/common/transform.h"
#include "core/sim/noise.h"
#include "core/sim/pose_drift.h"
#include "core/sim/renderer.h"

namespace objdb::sim {

struct SceneObject {
  int id = 0;                     // instance id in the ground-truth masks, 1..65535
  std::string category;           // object kind ("round_chair", "floor", "wall", ...)
  std::string mesh;               // library kind, or "file:<path>" (relative to the scene file)
  Eigen::Vector3f scale = Eigen::Vector3f::Ones();  // applied to the mesh in the object frame
  std::vector<float> size;        // sized kinds (sizeArity()): floor {x, y}, wall {length,
                                  // height}, base_cabinet {width}, ...; empty = default size
  Rgb8 albedo{180, 180, 180};
  Transform T_world_object = Transform::Identity();
  bool structure = false;         // floor, walls, built-in furniture: background for
                                  // object-level evaluation
};

// An instance of the library kind `kind` (its category and its mesh).
SceneObject makeSceneObject(int id, const std::string& kind, const Transform& T_world_object,
                            Rgb8 albedo, bool structure = false, std::vector<float> size = {});

struct Keyframe {
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // camera centre, world frame
  Eigen::Vector3d look_at = Eigen::Vector3d::UnitX();  // point the optical axis goes through
};

struct TrajectorySpec {
  int frames = 300;      // frames sampled along the keyframes
  double fps = 30.0;     // timestamps = index / fps
  bool closed = false;   // loop back from the last keyframe to the first
  std::vector<Keyframe> keyframes;
};

struct Scene {
  std::string name = "scene";
  std::string camera_preset;      // "vga" / "tango" / empty when custom
  Intrinsics intrinsics = Intrinsics::tango();
  double depth_scale_m = 0.001;   // metres per unit of the written 16-bit depth
  DepthNoiseParams noise;
  PoseDrift drift;                // error of the written poses (default: none)
  std::vector<SceneObject> objects;
  TrajectorySpec trajectory;
  std::filesystem::path base_dir; // where "file:" meshes are resolved
  Status validate() const;
};

StatusOr<Scene> parseSceneJson(absl::string_view text, const std::filesystem::path& base_dir);
StatusOr<Scene> loadSceneFile(const std::filesystem::path& path);
std::string sceneToJson(const Scene& scene);

// Samples the camera poses T_world_camera of the trajectory (Catmull–Rom through positions and
// look-at points, uniform in keyframe parameter, image up ≈ world +z).
StatusOr<std::vector<Transform>> sampleTrajectory(const TrajectorySpec& trajectory);

// The meshes of a scene, built once, and the render list pointing into them.
struct BuiltScene {
  std::vector<TriangleMesh> meshes;        // one per distinct (mesh, scale, size)
  std::vector<RenderInstance> instances;   // one per object, pointing into meshes
};
StatusOr<BuiltScene> buildScene(const Scene& scene);

// Every instance's mesh (objects, floor, walls) in the world frame: the scene's true surfaces.
TriangleMesh trueSurface(const BuiltScene& built);

}  // namespace objdb::sim
