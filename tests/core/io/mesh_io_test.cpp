#include "core/io/mesh_io.h"

#include <cstring>
#include <fstream>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/support/meshes.h"

#include "tests/support/temp_dir.h"

namespace objdb::io {
namespace {

namespace fs = std::filesystem;
using objdb::testing::TempDir;
using objdb::testing::writeTextFile;
using ::testing::HasSubstr;

TriangleMesh unitCube() { return objdb::testing::unitCubeMesh(); }

TriangleMesh colouredCube() {
  TriangleMesh mesh = unitCube();
  for (auto& v : mesh.vertices) v = v * 0.3f + Eigen::Vector3f(-1.0f / 3.0f, 1e-7f, 12.5f);
  mesh.computeVertexNormals();
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    mesh.colors.push_back({uint8_t(30 * i), uint8_t(255 - i), uint8_t(i % 2 ? 255 : 0)});
  }
  return mesh;
}

void writeBytes(const fs::path& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out << bytes;
}

std::string readBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void expectSameMesh(const TriangleMesh& a, const TriangleMesh& b) {
  EXPECT_EQ(a.vertices, b.vertices);
  EXPECT_EQ(a.normals, b.normals);
  EXPECT_EQ(a.colors, b.colors);
  EXPECT_EQ(a.triangles, b.triangles);
}

TEST(PlyMesh, BinaryRoundTripIsExact) {
  TempDir dir;
  const TriangleMesh mesh = colouredCube();
  ASSERT_TRUE(writePlyMesh(dir / "cube.ply", mesh).ok());
  EXPECT_THAT(readBytes(dir / "cube.ply"), HasSubstr("format binary_little_endian 1.0"));
  const auto back = readMesh(dir / "cube.ply");
  ASSERT_TRUE(back.ok()) << back.status();
  expectSameMesh(*back, mesh);
}

TEST(PlyMesh, AsciiRoundTripIsExact) {
  TempDir dir;
  const TriangleMesh mesh = colouredCube();
  ASSERT_TRUE(writePlyMesh(dir / "cube.PLY", mesh, /*ascii=*/true).ok());
  EXPECT_THAT(readBytes(dir / "cube.PLY"), HasSubstr("format ascii 1.0"));
  const auto back = readMesh(dir / "cube.PLY");
  ASSERT_TRUE(back.ok()) << back.status();
  expectSameMesh(*back, mesh);
  EXPECT_NEAR(back->signedVolume(), 0.027, 1e-6);
}

TEST(PlyCloud, RoundTripBothEncodings) {
  TempDir dir;
  PointCloud cloud;
  for (int i = 0; i < 50; ++i) {
    cloud.points.emplace_back(0.01f * float(i), -0.5f * float(i % 7), 1.0f / float(i + 1));
    cloud.normals.emplace_back(0.0f, 0.6f, 0.8f);
    cloud.colors.push_back({uint8_t(i), uint8_t(2 * i), uint8_t(3 * i)});
  }
  for (bool ascii : {false, true}) {
    const fs::path path = dir / (ascii ? "cloud_ascii.ply" : "cloud_binary.ply");
    ASSERT_TRUE(writePlyCloud(path, cloud, ascii).ok());
    const auto back = readMesh(path);
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_EQ(back->vertices, cloud.points);
    EXPECT_EQ(back->normals, cloud.normals);
    EXPECT_EQ(back->colors, cloud.colors);
    EXPECT_TRUE(back->triangles.empty());
  }
  PointCloud bare;
  bare.points = cloud.points;
  ASSERT_TRUE(writePlyCloud(dir / "bare.ply", bare).ok());
  const auto back = readMesh(dir / "bare.ply");
  ASSERT_TRUE(back.ok());
  EXPECT_TRUE(back->normals.empty());
  EXPECT_TRUE(back->colors.empty());
}

TEST(PlyWriter, RejectsInconsistentInput) {
  TempDir dir;
  TriangleMesh mesh = unitCube();
  mesh.triangles.emplace_back(0, 1, 8);
  Status s = writePlyMesh(dir / "bad.ply", mesh);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("bad.ply"));
  EXPECT_FALSE(fs::exists(dir / "bad.ply"));

  PointCloud cloud;
  cloud.points = {Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(0, std::nanf(""), 0)};
  s = writePlyCloud(dir / "nan.ply", cloud);
  ASSERT_FALSE(s.ok());
  EXPECT_THAT(std::string(s.message()), HasSubstr("point 1 is not finite"));
  cloud.points[1].y() = 1.0f;
  cloud.colors.resize(1);
  EXPECT_FALSE(writePlyCloud(dir / "colours.ply", cloud).ok());
}

// A hand-written big-endian file with double coordinates, an int face count, an unknown vertex
// property (a list, even), an unknown element between vertices and faces, and a quad.
TEST(PlyMesh, ReadsBigEndianWithUnknownPropertiesAndElements) {
  std::string data =
      "ply\nformat binary_big_endian 1.0\ncomment hand-made\n"
      "element vertex 4\nproperty double x\nproperty double y\nproperty double z\n"
      "property list uchar short extra\nproperty float confidence\n"
      "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
      "element face 1\nproperty uchar flags\nproperty list int uint vertex_indices\n"
      "end_header\n";
  const auto be = [&](const void* p, size_t n) {
    const char* bytes = static_cast<const char*>(p);
    for (size_t i = 0; i < n; ++i) data += bytes[n - 1 - i];  // host is little endian
  };
  const double xyz[4][3] = {{0, 0, 0}, {2, 0, 0}, {2, 1, 0}, {0, 1, 0}};
  for (int v = 0; v < 4; ++v) {
    for (double c : xyz[v]) be(&c, 8);
    const uint8_t n = uint8_t(v % 2 ? 2 : 0);
    data += char(n);
    for (int k = 0; k < n; ++k) {
      const int16_t junk = int16_t(-7 * k);
      be(&junk, 2);
    }
    const float confidence = 0.5f;
    be(&confidence, 4);
  }
  const int32_t edge[2] = {0, 1};
  be(&edge[0], 4);
  be(&edge[1], 4);
  data += char(9);  // flags
  const int32_t count = 4;
  be(&count, 4);
  for (uint32_t i : {0u, 1u, 2u, 3u}) be(&i, 4);

  TempDir dir;
  writeBytes(dir / "be.ply", data);
  const auto mesh = readMesh(dir / "be.ply");
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  ASSERT_EQ(mesh->vertices.size(), 4u);
  EXPECT_EQ(mesh->vertices[2], Eigen::Vector3f(2, 1, 0));
  ASSERT_EQ(mesh->triangles.size(), 2u);  // the quad, fanned
  EXPECT_EQ(mesh->triangles[0], Eigen::Vector3i(0, 1, 2));
  EXPECT_EQ(mesh->triangles[1], Eigen::Vector3i(0, 2, 3));
  EXPECT_NEAR(mesh->surfaceArea(), 2.0, 1e-9);
}

TEST(PlyMesh, AsciiWithVertexIndexNameAndFloatColours) {
  TempDir dir;
  ASSERT_TRUE(writeTextFile(dir / "a.ply",
                            "ply\r\nformat ascii 1.0\r\ncomment Windows line ends\r\n"
                            "element vertex 3\r\nproperty float x\r\nproperty float y\r\n"
                            "property float z\r\nproperty float red\r\nproperty float green\r\n"
                            "property float blue\r\nelement face 1\r\n"
                            "property list ushort int vertex_index\r\nend_header\r\n"
                            "0 0 0 1 0 0.5\r\n1 0 0 0 1 0\r\n0 1 0 0 0 1\r\n3 0 1 2\r\n"));
  const auto mesh = readMesh(dir / "a.ply");
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  ASSERT_EQ(mesh->colors.size(), 3u);
  EXPECT_EQ(mesh->colors[0], (Rgb8{255, 0, 128}));
  EXPECT_EQ(mesh->triangles.size(), 1u);
}

TEST(PlyMesh, TruncatedBinaryNamesElementAndProperty) {
  TempDir dir;
  ASSERT_TRUE(writePlyMesh(dir / "cube.ply", unitCube()).ok());
  const std::string bytes = readBytes(dir / "cube.ply");
  writeBytes(dir / "cut.ply", bytes.substr(0, bytes.size() - 10));
  const auto mesh = readMesh(dir / "cut.ply");
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.status().code(), absl::StatusCode::kInvalidArgument);
  const std::string message(mesh.status().message());
  EXPECT_THAT(message, HasSubstr("cut.ply"));
  EXPECT_THAT(message, HasSubstr("element 'face' 11"));
  EXPECT_THAT(message, HasSubstr("vertex_indices"));
  EXPECT_THAT(message, HasSubstr("end of file"));
}

TEST(PlyMesh, AbsurdVertexCountFailsBeforeAllocating) {
  TempDir dir;
  for (const char* format : {"binary_little_endian", "ascii"}) {
    SCOPED_TRACE(format);
    ASSERT_TRUE(writeTextFile(dir / "huge.ply",
                              absl::StrCat("ply\nformat ", format, " 1.0\n",
                                           "element vertex 1000000000000\nproperty float x\n"
                                           "property float y\nproperty float z\nend_header\n",
                                           std::string(600, '0'))));
    const auto mesh = readMesh(dir / "huge.ply");
    ASSERT_FALSE(mesh.ok());
    EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("huge.ply"));
    EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("1000000000000"));
  }
  ASSERT_TRUE(writeTextFile(dir / "faces.ply",
                            "ply\nformat binary_little_endian 1.0\nelement vertex 0\n"
                            "property float x\nproperty float y\nproperty float z\n"
                            "element face 4000000000\nproperty list uchar int vertex_indices\n"
                            "end_header\n0123456789"));
  const auto faces = readMesh(dir / "faces.ply");
  ASSERT_FALSE(faces.ok());
  EXPECT_THAT(std::string(faces.status().message()), HasSubstr("'face' elements"));
}

TEST(PlyMesh, BadContentNamesLine) {
  TempDir dir;
  const std::string header =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n";
  const auto check = [&](const std::string& body, const std::string& expected) {
    ASSERT_TRUE(writeTextFile(dir / "m.ply", header + body));
    const auto mesh = readMesh(dir / "m.ply");
    ASSERT_FALSE(mesh.ok()) << body;
    EXPECT_THAT(std::string(mesh.status().message()), HasSubstr(expected)) << body;
  };
  check("0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "m.ply line 13: element 'face' 0");
  check("0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", "vertex index 3 is outside 0..2");
  check("0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n", "m.ply line 11: element 'vertex' 1");
  check("0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", "not finite");
  check("0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "face has 2 vertices");
  check("0 0 0\n1 0 0\n0 1 0\n3 0 1.5 2\n", "'1.5' is not a valid value");
  check("0 0 0\n1 0 0\n0 1 0\n3 0 1\n", "unexpected end of file");

  const auto header_error = [&](const std::string& text, const std::string& expected) {
    ASSERT_TRUE(writeTextFile(dir / "h.ply", text));
    const auto mesh = readMesh(dir / "h.ply");
    ASSERT_FALSE(mesh.ok()) << text;
    EXPECT_THAT(std::string(mesh.status().message()), HasSubstr(expected)) << text;
  };
  header_error("ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n",
               "h.ply line 4: unknown PLY type 'half'");
  header_error("ply\nformat ascii 1.0\nelement vertex -1\nend_header\n", "h.ply line 3");
  header_error("ply\nformat ascii 2.0\nend_header\n", "h.ply line 2");
  header_error("ply\nformat ascii 1.0\nelement vertex 0\n", "no end_header");
  header_error("PLY\n", "not a PLY file");
  header_error("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n",
               "lacks one of the scalar properties x, y, z");
}

TEST(ObjMesh, QuadsNegativeIndicesAndSlashForms) {
  TempDir dir;
  ASSERT_TRUE(writeTextFile(dir / "cube.obj",
                            "# unit cube\nmtllib cube.mtl\no cube\n"
                            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"
                            "v 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1 1.0\n"
                            "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                            "vn 0 0 -1\nvn 0 0 1\n"
                            "usemtl grey\ns off\n"
                            "f 1/1/1 3/2/1 4/3/1 2/4/1\n"  // bottom, v/vt/vn
                            "f -4//2 -3//2 -1//2 -2//2\n"  // top, negative, v//vn
                            "f 1/1 2/2 6/3 5/4\n"          // v/vt
                            "f 3 7 8 4\n"
                            "f 1 5 7 3\n"
                            "f 2 4 8 6\n"));
  const auto mesh = readMesh(dir / "cube.obj");
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(mesh->vertices.size(), 8u);
  EXPECT_EQ(mesh->triangles.size(), 12u);
  EXPECT_EQ(mesh->triangles[2], Eigen::Vector3i(4, 5, 7));  // first triangle of the top quad
  EXPECT_NEAR(mesh->surfaceArea(), 6.0, 1e-9);
  EXPECT_NEAR(mesh->signedVolume(), 1.0, 1e-9);
}

TEST(ObjMesh, BadFaceIndexNamesFileAndLine) {
  TempDir dir;
  const auto check = [&](const std::string& text, const std::string& expected) {
    ASSERT_TRUE(writeTextFile(dir / "bad.obj", text));
    const auto mesh = readMesh(dir / "bad.obj");
    ASSERT_FALSE(mesh.ok()) << text;
    EXPECT_EQ(mesh.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_THAT(std::string(mesh.status().message()), HasSubstr(expected)) << text;
  };
  const std::string three = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
  check(three + "f 1 2 4\n", "bad.obj line 4: face refers to vertex 4");
  check(three + "f 1 2 0\n", "bad.obj line 4: face vertex '0'");
  check(three + "f 1 2 -4\n", "bad.obj line 4: face vertex '-4'");
  check(three + "f 1 2 x\n", "bad.obj line 4");
  check(three + "f 1 2/1/1/1 3\n", "bad.obj line 4");
  check(three + "f 1 2\n", "bad.obj line 4: face has 2 vertices");
  check("v 0 0\n", "bad.obj line 1: vertex needs x y z");
  check("v 0 0 inf\n", "bad.obj line 1: vertex is not finite");
  check(three + "f 1 2 3\nf 3 2 9\nf 1 2 3\n", "bad.obj line 5");
}

TEST(StlMesh, AsciiCubeMergesVertices) {
  TempDir dir;
  const TriangleMesh cube = unitCube();
  std::string text = "solid cube\n";
  for (const auto& t : cube.triangles) {
    absl::StrAppend(&text, "  facet normal 0 0 0\n    outer loop\n");
    for (int k = 0; k < 3; ++k) {
      const auto& v = cube.vertices[size_t(t[k])];
      absl::StrAppend(&text, "      vertex ", v.x(), " ", v.y(), " ", v.z(), "\n");
    }
    absl::StrAppend(&text, "    endloop\n  endfacet\n");
  }
  text += "endsolid cube\n";
  ASSERT_TRUE(writeTextFile(dir / "cube.stl", text));
  const auto mesh = readMesh(dir / "cube.stl");
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(mesh->vertices.size(), 8u);
  EXPECT_EQ(mesh->triangles.size(), 12u);
  EXPECT_NEAR(mesh->signedVolume(), 1.0, 1e-9);

  ASSERT_TRUE(writeTextFile(dir / "bad.stl",
                            "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
                            "vertex 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n"));
  const auto bad = readMesh(dir / "bad.stl");
  ASSERT_FALSE(bad.ok());
  EXPECT_THAT(std::string(bad.status().message()), HasSubstr("bad.stl line 5"));

  ASSERT_TRUE(writeTextFile(dir / "open.stl", "solid x\nfacet normal 0 0 1\n"));
  EXPECT_THAT(std::string(readMesh(dir / "open.stl").status().message()),
              HasSubstr("missing endsolid"));
}

std::string binaryStl(const TriangleMesh& mesh, const std::string& header) {
  std::string data = header;
  data.resize(80, ' ');
  const uint32_t count = uint32_t(mesh.triangles.size());
  data.append(reinterpret_cast<const char*>(&count), 4);
  for (const auto& t : mesh.triangles) {
    const float normal[3] = {0, 0, 0};
    data.append(reinterpret_cast<const char*>(normal), 12);
    for (int k = 0; k < 3; ++k) {
      data.append(reinterpret_cast<const char*>(mesh.vertices[size_t(t[k])].data()), 12);
    }
    data.append(2, '\0');
  }
  return data;
}

TEST(StlMesh, BinaryCubeEvenWithSolidHeader) {
  TempDir dir;
  writeBytes(dir / "cube.stl", binaryStl(unitCube(), "solid but actually binary"));
  const auto mesh = readMesh(dir / "cube.stl");
  ASSERT_TRUE(mesh.ok()) << mesh.status();
  EXPECT_EQ(mesh->vertices.size(), 8u);
  EXPECT_EQ(mesh->triangles.size(), 12u);
  EXPECT_NEAR(mesh->surfaceArea(), 6.0, 1e-9);
  EXPECT_NEAR(mesh->signedVolume(), 1.0, 1e-9);
}

TEST(StlMesh, BinaryWithWrongCountIsRejected) {
  TempDir dir;
  std::string data = binaryStl(unitCube(), "binary");
  const uint32_t huge = 3000000000u;
  std::memcpy(data.data() + 80, &huge, 4);
  writeBytes(dir / "lying.stl", data);
  const auto mesh = readMesh(dir / "lying.stl");
  ASSERT_FALSE(mesh.ok());
  EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("lying.stl"));
  EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("3000000000 triangles"));

  writeBytes(dir / "short.stl", "tiny");
  EXPECT_THAT(std::string(readMesh(dir / "short.stl").status().message()), HasSubstr("too short"));
}

// Random byte corruptions and truncations of valid files of every format: each read either
// succeeds with a valid mesh or fails with a message naming the file; it never crashes.
TEST(ReadMesh, CorruptedFilesFailCleanly) {
  TempDir dir;
  const TriangleMesh cube = colouredCube();
  ASSERT_TRUE(writePlyMesh(dir / "binary.ply", cube).ok());
  ASSERT_TRUE(writePlyMesh(dir / "ascii.ply", cube, true).ok());
  ASSERT_TRUE(writeTextFile(dir / "mesh.obj",
                            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\n"
                            "f 1//1 2//1 3//1\nf -4 -2 -3\nf 2/1/1 4/1/1 3/1/1\n"));
  std::string stl = "solid s\n";
  for (const auto& t : cube.triangles) {
    stl += "facet normal 0 0 1\nouter loop\n";
    for (int k = 0; k < 3; ++k) {
      const auto& v = cube.vertices[size_t(t[k])];
      absl::StrAppend(&stl, "vertex ", v.x(), " ", v.y(), " ", v.z(), "\n");
    }
    stl += "endloop\nendfacet\n";
  }
  stl += "endsolid s\n";
  ASSERT_TRUE(writeTextFile(dir / "ascii.stl", stl));
  writeBytes(dir / "binary.stl", binaryStl(unitCube(), "binary"));

  std::mt19937 random(12345);
  size_t failures = 0;
  for (const char* name : {"binary.ply", "ascii.ply", "mesh.obj", "ascii.stl", "binary.stl"}) {
    const std::string original = readBytes(dir / name);
    const fs::path corrupt = dir / (std::string("corrupt_") + name);
    for (int trial = 0; trial < 300; ++trial) {
      std::string bytes = original;
      if (trial % 3 == 0) {
        bytes.resize(random() % bytes.size());
      } else {
        const int flips = 1 + int(random() % 4);
        for (int f = 0; f < flips; ++f) {
          const size_t at = random() % bytes.size();
          bytes[at] = trial % 3 == 1 ? char(random() % 256) : "0123456789 -.\n/e"[random() % 16];
        }
      }
      writeBytes(corrupt, bytes);
      const auto mesh = readMesh(corrupt);
      if (mesh.ok()) {
        EXPECT_TRUE(mesh->validate().ok()) << name << " trial " << trial;
      } else {
        ++failures;
        EXPECT_THAT(std::string(mesh.status().message()), HasSubstr(corrupt.string()))
            << name << " trial " << trial;
      }
    }
  }
  EXPECT_GT(failures, 300u);  // most corruptions are detected
}

TEST(ReadMesh, UnknownExtensionAndMissingFile) {
  TempDir dir;
  auto mesh = readMesh(dir / "cow.off");
  ASSERT_FALSE(mesh.ok());
  EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("'.off'"));
  mesh = readMesh(dir / "missing.ply");
  ASSERT_FALSE(mesh.ok());
  EXPECT_EQ(mesh.status().code(), absl::StatusCode::kNotFound);
  EXPECT_THAT(std::string(mesh.status().message()), HasSubstr("missing.ply"));
}

}  // namespace
}  // namespace objdb::io
