// `objdb gsm`: segments and fuses a tiny synthetic dataset, checks the label-coloured mesh and the
// raw segments it writes.
#include <gtest/gtest.h>

#include <filesystem>
#include <set>
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

TEST(GsmCommand, WritesALabelColouredMeshAndTheRawSegments) {
  testing::TempDir dir;
  const fs::path dataset = dir / "boxes";
  ProcessResult r = runProcess({kObjdb, "sim", "--preset", "two-boxes", "--frames", "8",
                                "--no-noise", "--out", dataset.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const fs::path mesh_path = dir / "labels.ply", segments = dir / "segments";
  r = runProcess({kObjdb, "gsm", "--dataset", dataset.string(), "--out", mesh_path.string(),
                  "--segments-out", segments.string()});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  StatusOr<TriangleMesh> mesh = io::readMesh(mesh_path);
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  ASSERT_EQ(mesh->colors.size(), mesh->vertices.size());
  std::set<int> colours;
  for (const Rgb8& c : mesh->colors) colours.insert((c.r << 16) | (c.g << 8) | c.b);
  EXPECT_GE(colours.size(), 3u) << "floor and the two boxes carry different labels";
  size_t files = 0;
  for (const auto& entry : fs::directory_iterator(segments)) {
    ++files;
    StatusOr<TriangleMesh> segment = io::readMesh(entry.path());
    ASSERT_TRUE(segment.ok()) << segment.status();
  }
  EXPECT_GE(files, 3u);
}

TEST(GsmCommand, MissingArgumentsAndBadConfigAreClearErrors) {
  ProcessResult r = runProcess({kObjdb, "gsm", "--dataset", "d"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--dataset and --out are required"), std::string::npos) << r.err;
  testing::TempDir dir;
  ASSERT_TRUE(testing::writeTextFile(dir / "bad.json", R"({"gsm": {"merge_min_frames": 0}})"));
  r = runProcess({kObjdb, "gsm", "--dataset", "d", "--out", "o.ply", "--config",
                  (dir / "bad.json").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("gsm.merge_min_frames"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace objdb
