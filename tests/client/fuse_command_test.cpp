// `objdb fuse`: fuses a tiny synthetic dataset written by `objdb sim` and checks the mesh it
// writes against the scene, and its errors.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "core/io/mesh_io.h"
#include "tests/support/subprocess.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::ProcessResult;
using testing::runProcess;
namespace fs = std::filesystem;

const std::string kObjdb = OBJDB_CLIENT_BINARY;

TEST(FuseCommand, WritesTheSurfaceOfTheScene) {
  testing::TempDir dir;
  const fs::path dataset = dir / "boxes";
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "6",
                                "--camera", "tango", "--no-noise", "--out", dataset.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path mesh_path = dir / "boxes.ply";
  r = runProcess({kObjdb, "fuse", "--dataset", dataset.string(), "--out", mesh_path.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  EXPECT_NE(r.out.find("6 frames fused (0 skipped)"), std::string::npos) << r.out;
  StatusOr<TriangleMesh> mesh = io::readMesh(mesh_path);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  ASSERT_GT(mesh->triangles.size(), 1000u);
  // The two-boxes scene: a floor at z = 0 and two boxes at most 0.5 m high, near the origin.
  for (const auto& v : mesh->vertices) {
    ASSERT_GT(v.z(), -0.05f);
    ASSERT_LT(v.z(), 0.55f);
  }
}

TEST(FuseCommand, BadArgumentsAndMissingDatasetAreClearErrors) {
  ProcessResult r = runProcess({kObjdb, "fuse", "--out", "x.ply"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--dataset and --out are required"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "fuse", "--dataset", "/nonexistent/ds", "--out", "/tmp/x.ply"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("/nonexistent/ds"), std::string::npos) << r.err;
  r = runProcess({kObjdb, "fuse", "--dataset", "d", "--out", "o.ply", "--voxel-size", "-1"});
  EXPECT_EQ(r.exit_code, 2);
  r = runProcess({kObjdb, "fuse", "--dataset", "d", "--out", "o.ply", "--voxel-size", "3"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("tsdf.voxel_size_m"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace objdb
