#include "core/sim/scene.h"

#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/io/mesh_io.h"
#include "core/sim/object_library.h"

namespace objdb::sim {

SceneObject makeSceneObject(int id, const std::string& kind, const Transform& T_world_object,
                            Rgb8 albedo, bool structure, std::vector<float> size) {
  SceneObject o;
  o.id = id;
  o.category = kind;
  o.mesh = kind;
  o.albedo = albedo;
  o.T_world_object = T_world_object;
  o.structure = structure;
  o.size = std::move(size);
  return o;
}
namespace {

using nlohmann::json;
constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

Status fieldError(const std::string& where, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat("scene ", where, ": ", what));
}

StatusOr<Eigen::Vector3d> readVec3(const json& j, const std::string& where) {
  if (!j.is_array() || j.size() != 3 || !j[0].is_number() || !j[1].is_number() ||
      !j[2].is_number()) {
    return fieldError(where, absl::StrCat("expected [x, y, z] numbers, got ", j.dump()));
  }
  Eigen::Vector3d v(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
  if (!v.allFinite()) return fieldError(where, "values must be finite");
  return v;
}

StatusOr<Transform> readPose(const json& j, const std::string& where) {
  if (!j.is_object() || !j.contains("t")) return fieldError(where, "expected {\"t\": [...], ...}");
  OBJDB_ASSIGN_OR_RETURN(Eigen::Vector3d t, readVec3(j["t"], where + ".t"));
  if (j.contains("q")) {
    const json& q = j["q"];
    if (!q.is_array() || q.size() != 4) return fieldError(where + ".q", "expected [qx, qy, qz, qw]");
    std::array<double, 4> q_xyzw{};
    for (int i = 0; i < 4; ++i) {
      if (!q[i].is_number()) return fieldError(where + ".q", "expected numbers");
      q_xyzw[i] = q[i].get<double>();
    }
    auto T = transformFromTranslationQuaternion(t, q_xyzw);
    if (!T.ok()) return fieldError(where, std::string(T.status().message()));
    return *T;
  }
  double yaw_deg = 0.0;
  if (j.contains("yaw_deg")) {
    if (!j["yaw_deg"].is_number()) return fieldError(where + ".yaw_deg", "expected a number");
    yaw_deg = j["yaw_deg"].get<double>();
    if (!std::isfinite(yaw_deg)) return fieldError(where + ".yaw_deg", "must be finite");
  }
  return poseFromXyzYaw(t, yaw_deg * kDegToRad);
}

json poseToJson(const Transform& T) {
  const TumPose p = tumPoseFromTransform(T, 0.0);
  return json{{"t", {p.t.x(), p.t.y(), p.t.z()}},
              {"q", {p.q_xyzw[0], p.q_xyzw[1], p.q_xyzw[2], p.q_xyzw[3]}}};
}

Status checkKeys(const json& j, const std::set<std::string>& known, const std::string& where) {
  for (const auto& [key, value] : j.items()) {
    if (!known.count(key)) return fieldError(where, absl::StrCat("unknown key '", key, "'"));
  }
  return absl::OkStatus();
}

template <typename T>
Status readNumber(const json& j, const char* key, const std::string& where, T* out) {
  if (!j.contains(key)) return absl::OkStatus();
  if (!j[key].is_number()) return fieldError(where + "." + key, "expected a number");
  *out = j[key].get<T>();
  return absl::OkStatus();
}

Status parseNoise(const json& j, DepthNoiseParams* noise) {
  const std::string w = "noise";
  if (!j.is_object()) return fieldError(w, "expected an object");
  OBJDB_RETURN_IF_ERROR(checkKeys(
      j,
      {"enabled", "seed", "sigma_base_m", "sigma_quadratic", "sigma_reference_m", "quantum_m",
       "disparity_quantum", "min_depth_m", "max_depth_m", "grazing_start_deg", "grazing_full_deg",
       "edge_jump_m", "edge_dropout_probability"},
      w));
  if (j.contains("enabled")) {
    if (!j["enabled"].is_boolean()) return fieldError(w + ".enabled", "expected true/false");
    noise->enabled = j["enabled"].get<bool>();
  }
  if (j.contains("seed")) {
    if (!j["seed"].is_number_unsigned()) return fieldError(w + ".seed", "expected an unsigned integer");
    noise->seed = j["seed"].get<uint64_t>();
  }
  OBJDB_RETURN_IF_ERROR(readNumber(j, "sigma_base_m", w, &noise->sigma_base_m));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "sigma_quadratic", w, &noise->sigma_quadratic));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "sigma_reference_m", w, &noise->sigma_reference_m));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "quantum_m", w, &noise->quantum_m));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "disparity_quantum", w, &noise->disparity_quantum));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "min_depth_m", w, &noise->min_depth_m));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "max_depth_m", w, &noise->max_depth_m));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "grazing_start_deg", w, &noise->grazing_start_deg));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "grazing_full_deg", w, &noise->grazing_full_deg));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "edge_jump_m", w, &noise->edge_jump_m));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "edge_dropout_probability", w, &noise->edge_dropout_probability));
  return noise->validate();
}

json noiseToJson(const DepthNoiseParams& n) {
  json j{{"enabled", n.enabled},
         {"seed", n.seed},
         {"sigma_base_m", n.sigma_base_m},
         {"sigma_quadratic", n.sigma_quadratic},
         {"sigma_reference_m", n.sigma_reference_m},
         {"quantum_m", n.quantum_m},
         {"min_depth_m", n.min_depth_m},
         {"max_depth_m", n.max_depth_m},
         {"grazing_start_deg", n.grazing_start_deg},
         {"grazing_full_deg", n.grazing_full_deg},
         {"edge_jump_m", n.edge_jump_m},
         {"edge_dropout_probability", n.edge_dropout_probability}};
  // Written only when on, so scene files from before the field stay byte-identical.
  if (n.disparity_quantum != 0.0f) j["disparity_quantum"] = n.disparity_quantum;
  return j;
}

Status parseDrift(const json& j, PoseDrift* drift) {
  const std::string w = "drift";
  if (!j.is_object()) return fieldError(w, "expected an object");
  OBJDB_RETURN_IF_ERROR(checkKeys(j, {"translation_m", "rotation_deg", "seed"}, w));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "translation_m", w, &drift->translation_m));
  OBJDB_RETURN_IF_ERROR(readNumber(j, "rotation_deg", w, &drift->rotation_deg));
  if (j.contains("seed")) {
    if (!j["seed"].is_number_unsigned()) {
      return fieldError(w + ".seed", "expected an unsigned integer");
    }
    drift->seed = j["seed"].get<uint64_t>();
  }
  return drift->validate();
}

StatusOr<SceneObject> parseObject(const json& j, size_t index) {
  const std::string w = absl::StrCat("objects[", index, "]");
  if (!j.is_object()) return fieldError(w, "expected an object");
  OBJDB_RETURN_IF_ERROR(
      checkKeys(j, {"id", "category", "mesh", "scale", "size", "albedo", "structure", "pose"}, w));
  SceneObject o;
  if (!j.contains("id") || !j["id"].is_number_integer()) return fieldError(w + ".id", "expected an integer id");
  const int64_t id = j["id"].get<int64_t>();
  if (!(id >= 1 && id <= 65535)) return fieldError(w + ".id", absl::StrCat("must be in 1..65535 (got ", id, ")"));
  o.id = static_cast<int>(id);
  if (!j.contains("category") || !j["category"].is_string()) return fieldError(w + ".category", "expected a string");
  o.category = j["category"].get<std::string>();
  o.mesh = o.category;
  if (j.contains("mesh")) {
    if (!j["mesh"].is_string()) return fieldError(w + ".mesh", "expected a string");
    o.mesh = j["mesh"].get<std::string>();
  }
  if (j.contains("scale")) {
    OBJDB_ASSIGN_OR_RETURN(Eigen::Vector3d s, readVec3(j["scale"], w + ".scale"));
    if (!(s.minCoeff() > 0)) return fieldError(w + ".scale", "must be > 0");
    o.scale = s.cast<float>();
  }
  if (j.contains("size")) {
    const json& s = j["size"];
    if (!s.is_array() || s.empty() || s.size() > 2) {
      return fieldError(w + ".size", "expected one or two positive sizes in metres");
    }
    for (const auto& v : s) {
      if (!(v.is_number() && v.get<double>() > 0 && v.get<double>() < 1000)) {
        return fieldError(w + ".size", "expected one or two positive sizes in metres");
      }
      o.size.push_back(v.get<float>());
    }
  }
  if (j.contains("albedo")) {
    const json& a = j["albedo"];
    if (!a.is_array() || a.size() != 3) return fieldError(w + ".albedo", "expected [r, g, b] in 0..255");
    int rgb[3];
    for (int k = 0; k < 3; ++k) {
      if (!a[k].is_number_integer() || a[k].get<int>() < 0 || a[k].get<int>() > 255) {
        return fieldError(w + ".albedo", "expected [r, g, b] in 0..255");
      }
      rgb[k] = a[k].get<int>();
    }
    o.albedo = Rgb8{uint8_t(rgb[0]), uint8_t(rgb[1]), uint8_t(rgb[2])};
  }
  if (j.contains("structure")) {
    if (!j["structure"].is_boolean()) return fieldError(w + ".structure", "expected true/false");
    o.structure = j["structure"].get<bool>();
  }
  if (j.contains("pose")) {
    OBJDB_ASSIGN_OR_RETURN(o.T_world_object, readPose(j["pose"], w + ".pose"));
  }
  return o;
}

Eigen::Vector3d catmullRom(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1,
                           const Eigen::Vector3d& p2, const Eigen::Vector3d& p3, double t) {
  const double t2 = t * t, t3 = t2 * t;
  return 0.5 * ((2.0 * p1) + (-p0 + p2) * t + (2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3) * t2 +
                (-p0 + 3.0 * p1 - 3.0 * p2 + p3) * t3);
}

}  // namespace

Status Scene::validate() const {
  OBJDB_RETURN_IF_ERROR(intrinsics.validate());
  if (!(std::isfinite(depth_scale_m) && depth_scale_m > 0 && depth_scale_m <= 0.01)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("scene depth_scale_m must be in (0, 0.01] (got %g)", depth_scale_m));
  }
  OBJDB_RETURN_IF_ERROR(noise.validate());
  OBJDB_RETURN_IF_ERROR(drift.validate());
  std::set<int> ids;
  for (const auto& o : objects) {
    if (!ids.insert(o.id).second) {
      return absl::InvalidArgumentError(absl::StrCat("scene: object id ", o.id, " is used twice"));
    }
    OBJDB_RETURN_IF_ERROR(validateTransform(o.T_world_object, absl::StrCat("pose of object ", o.id)));
  }
  if (!(trajectory.frames >= 1 && trajectory.frames <= 1000000)) {
    return absl::InvalidArgumentError(
        absl::StrCat("scene trajectory.frames must be in 1..1000000 (got ", trajectory.frames, ")"));
  }
  if (!(std::isfinite(trajectory.fps) && trajectory.fps > 0)) {
    return absl::InvalidArgumentError("scene trajectory.fps must be > 0");
  }
  if (trajectory.keyframes.size() < 2) {
    return absl::InvalidArgumentError(absl::StrCat(
        "scene trajectory needs at least 2 keyframes (got ", trajectory.keyframes.size(), ")"));
  }
  return absl::OkStatus();
}

StatusOr<Scene> parseSceneJson(absl::string_view text, const std::filesystem::path& base_dir) {
  json root;
  try {
    root = json::parse(text.begin(), text.end());
  } catch (const json::exception& e) {  // parse_error, and out_of_range for numbers like 1E99999
    return absl::InvalidArgumentError(absl::StrCat("scene is not valid JSON: ", e.what()));
  }
  if (!root.is_object()) return fieldError("root", "expected a JSON object");
  OBJDB_RETURN_IF_ERROR(checkKeys(
      root, {"name", "camera", "depth_scale_m", "noise", "drift", "objects", "trajectory"},
      "root"));
  Scene scene;
  scene.base_dir = base_dir;
  if (root.contains("name")) {
    if (!root["name"].is_string()) return fieldError("name", "expected a string");
    scene.name = root["name"].get<std::string>();
  }
  if (root.contains("camera")) {
    const json& c = root["camera"];
    if (c.is_string()) {
      scene.camera_preset = c.get<std::string>();
      auto k = intrinsicsPreset(scene.camera_preset);
      if (!k.ok()) return fieldError("camera", std::string(k.status().message()));
      scene.intrinsics = *k;
    } else if (c.is_object()) {
      OBJDB_RETURN_IF_ERROR(checkKeys(c, {"width", "height", "fx", "fy", "cx", "cy"}, "camera"));
      Intrinsics k;
      for (const char* key : {"width", "height"}) {
        if (!c.contains(key) || !c[key].is_number_integer()) {
          return fieldError(absl::StrCat("camera.", key), "expected an integer");
        }
      }
      k.width = c["width"].get<int>();
      k.height = c["height"].get<int>();
      for (auto [key, field] : {std::pair{"fx", &k.fx}, {"fy", &k.fy}, {"cx", &k.cx}, {"cy", &k.cy}}) {
        if (!c.contains(key) || !c[key].is_number()) {
          return fieldError(absl::StrCat("camera.", key), "expected a number");
        }
        *field = c[key].get<double>();
      }
      scene.intrinsics = k;
    } else {
      return fieldError("camera", "expected \"vga\", \"tango\" or an intrinsics object");
    }
  }
  OBJDB_RETURN_IF_ERROR(readNumber(root, "depth_scale_m", "root", &scene.depth_scale_m));
  if (root.contains("noise")) OBJDB_RETURN_IF_ERROR(parseNoise(root["noise"], &scene.noise));
  if (root.contains("drift")) OBJDB_RETURN_IF_ERROR(parseDrift(root["drift"], &scene.drift));
  if (root.contains("objects")) {
    if (!root["objects"].is_array()) return fieldError("objects", "expected an array");
    for (size_t i = 0; i < root["objects"].size(); ++i) {
      OBJDB_ASSIGN_OR_RETURN(SceneObject o, parseObject(root["objects"][i], i));
      scene.objects.push_back(std::move(o));
    }
  }
  if (root.contains("trajectory")) {
    const json& t = root["trajectory"];
    if (!t.is_object()) return fieldError("trajectory", "expected an object");
    OBJDB_RETURN_IF_ERROR(checkKeys(t, {"frames", "fps", "closed", "keyframes"}, "trajectory"));
    if (t.contains("frames")) {
      if (!t["frames"].is_number_integer()) return fieldError("trajectory.frames", "expected an integer");
      const int64_t frames = t["frames"].get<int64_t>();
      if (!(frames >= 1 && frames <= 1000000)) return fieldError("trajectory.frames", "must be in 1..1000000");
      scene.trajectory.frames = static_cast<int>(frames);
    }
    OBJDB_RETURN_IF_ERROR(readNumber(t, "fps", "trajectory", &scene.trajectory.fps));
    if (t.contains("closed")) {
      if (!t["closed"].is_boolean()) return fieldError("trajectory.closed", "expected true/false");
      scene.trajectory.closed = t["closed"].get<bool>();
    }
    if (t.contains("keyframes")) {
      if (!t["keyframes"].is_array()) return fieldError("trajectory.keyframes", "expected an array");
      for (size_t i = 0; i < t["keyframes"].size(); ++i) {
        const json& k = t["keyframes"][i];
        const std::string w = absl::StrCat("trajectory.keyframes[", i, "]");
        if (!k.is_object()) return fieldError(w, "expected an object");
        OBJDB_RETURN_IF_ERROR(checkKeys(k, {"position", "look_at"}, w));
        Keyframe kf;
        OBJDB_ASSIGN_OR_RETURN(kf.position, readVec3(k.value("position", json()), w + ".position"));
        OBJDB_ASSIGN_OR_RETURN(kf.look_at, readVec3(k.value("look_at", json()), w + ".look_at"));
        scene.trajectory.keyframes.push_back(kf);
      }
    }
  }
  OBJDB_RETURN_IF_ERROR(scene.validate());
  return scene;
}

StatusOr<Scene> loadSceneFile(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open scene file ", path.string()));
  std::stringstream buffer;
  buffer << in.rdbuf();
  auto scene = parseSceneJson(buffer.str(), path.parent_path());
  if (!scene.ok()) return annotate(scene.status(), path.string());
  return scene;
}

std::string sceneToJson(const Scene& scene) {
  json root;
  root["name"] = scene.name;
  if (!scene.camera_preset.empty()) {
    root["camera"] = scene.camera_preset;
  } else {
    const auto& k = scene.intrinsics;
    root["camera"] = json{{"width", k.width}, {"height", k.height}, {"fx", k.fx},
                          {"fy", k.fy},       {"cx", k.cx},         {"cy", k.cy}};
  }
  root["depth_scale_m"] = scene.depth_scale_m;
  root["noise"] = noiseToJson(scene.noise);
  if (scene.drift.enabled()) {  // absent when off: older scene files stay byte-identical
    root["drift"] = json{{"translation_m", scene.drift.translation_m},
                         {"rotation_deg", scene.drift.rotation_deg},
                         {"seed", scene.drift.seed}};
  }
  json objects = json::array();
  for (const auto& o : scene.objects) {
    json j{{"id", o.id},
           {"category", o.category},
           {"mesh", o.mesh},
           {"albedo", {o.albedo.r, o.albedo.g, o.albedo.b}},
           {"structure", o.structure},
           {"pose", poseToJson(o.T_world_object)}};
    if (o.scale != Eigen::Vector3f::Ones()) j["scale"] = {o.scale.x(), o.scale.y(), o.scale.z()};
    if (!o.size.empty()) j["size"] = o.size;
    objects.push_back(j);
  }
  root["objects"] = objects;
  json keyframes = json::array();
  for (const auto& k : scene.trajectory.keyframes) {
    keyframes.push_back(json{{"position", {k.position.x(), k.position.y(), k.position.z()}},
                             {"look_at", {k.look_at.x(), k.look_at.y(), k.look_at.z()}}});
  }
  root["trajectory"] = json{{"frames", scene.trajectory.frames},
                            {"fps", scene.trajectory.fps},
                            {"closed", scene.trajectory.closed},
                            {"keyframes", keyframes}};
  return root.dump(2);
}

StatusOr<std::vector<Transform>> sampleTrajectory(const TrajectorySpec& trajectory) {
  const auto& kf = trajectory.keyframes;
  const int n = static_cast<int>(kf.size());
  if (n < 2) return absl::InvalidArgumentError("trajectory needs at least 2 keyframes");
  const int segments = trajectory.closed ? n : n - 1;
  auto key = [&](int i) -> const Keyframe& {
    if (trajectory.closed) return kf[((i % n) + n) % n];
    return kf[std::clamp(i, 0, n - 1)];
  };
  std::vector<Transform> poses;
  poses.reserve(trajectory.frames);
  for (int f = 0; f < trajectory.frames; ++f) {
    const double s = trajectory.frames == 1
                         ? 0.0
                         : double(f) * segments / (trajectory.closed ? trajectory.frames
                                                                      : trajectory.frames - 1);
    int i = std::min(static_cast<int>(std::floor(s)), segments - 1);
    const double t = s - i;
    const Eigen::Vector3d p = catmullRom(key(i - 1).position, key(i).position,
                                         key(i + 1).position, key(i + 2).position, t);
    const Eigen::Vector3d target = catmullRom(key(i - 1).look_at, key(i).look_at,
                                              key(i + 1).look_at, key(i + 2).look_at, t);
    auto T = lookAt(p, target);
    if (!T.ok()) return annotate(T.status(), absl::StrCat("trajectory frame ", f));
    poses.push_back(*T);
  }
  return poses;
}

StatusOr<BuiltScene> buildScene(const Scene& scene) {
  BuiltScene built;
  std::map<std::string, size_t> cache;
  std::vector<size_t> mesh_of_object;
  for (const auto& o : scene.objects) {
    const std::string key = absl::StrCat(o.mesh, "|", o.scale.x(), ",", o.scale.y(), ",",
                                         o.scale.z(), "|", o.size.empty() ? 0.f : o.size[0], ",",
                                         o.size.size() > 1 ? o.size[1] : 0.f);
    auto it = cache.find(key);
    if (it == cache.end()) {
      TriangleMesh mesh;
      if (absl::string_view(o.mesh).substr(0, 5) == "file:") {
        std::filesystem::path file = o.mesh.substr(5);
        if (file.is_relative()) file = scene.base_dir / file;
        auto loaded = io::readMesh(file);
        if (!loaded.ok()) return annotate(loaded.status(), absl::StrCat("object ", o.id));
        mesh = std::move(*loaded);
      } else if (o.mesh == "floor" && o.size.size() == 2) {
        mesh = makeFloor(o.size[0], o.size[1]);
      } else if (o.mesh == "wall" && o.size.size() == 2) {
        mesh = makeWall(o.size[0], o.size[1]);
      } else if (sizeArity(o.mesh) > 0 && !o.size.empty()) {
        auto made = makeSizedLibraryObject(o.mesh, o.size);
        if (!made.ok()) return annotate(made.status(), absl::StrCat("object ", o.id));
        mesh = std::move(*made);
      } else {
        auto made = makeLibraryObject(o.mesh);
        if (!made.ok()) return annotate(made.status(), absl::StrCat("object ", o.id));
        mesh = std::move(*made);
      }
      if (o.scale != Eigen::Vector3f::Ones()) scaleMesh(&mesh, o.scale);
      OBJDB_RETURN_IF_ERROR(annotate(mesh.validate(), absl::StrCat("mesh of object ", o.id)));
      it = cache.emplace(key, built.meshes.size()).first;
      built.meshes.push_back(std::move(mesh));
    }
    mesh_of_object.push_back(it->second);
  }
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    const auto& o = scene.objects[i];
    const TriangleMesh& mesh = built.meshes[mesh_of_object[i]];
    built.instances.push_back(RenderInstance{&mesh, o.T_world_object, uint16_t(o.id), o.albedo,
                                             boundingRadius(mesh)});
  }
  return built;
}

TriangleMesh trueSurface(const BuiltScene& built) {
  TriangleMesh out;
  for (const auto& instance : built.instances) {
    TriangleMesh m = *instance.mesh;
    m.transform(instance.T_world_object);
    out.append(m);
  }
  return out;
}

}  // namespace objdb::sim
