#include "core/io/mesh_io.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <climits>
#include <cmath>
#include <cstring>
#include <limits>
#include <new>
#include <unordered_map>

#include "core/io/io_util.h"

namespace objdb::io {
namespace {
namespace fs = std::filesystem;
using internal::LineReader;

constexpr uint64_t kMaxVertices = static_cast<uint64_t>(INT_MAX);

// Converts to float only when the value is finite in float (a double beyond the float range would
// otherwise be undefined behaviour to convert).
bool toFiniteFloats(const Eigen::Vector3d& in, Eigen::Vector3f* out) {
  const double kMax = std::numeric_limits<float>::max();
  if (!(in.allFinite() && in.cwiseAbs().maxCoeff() <= kMax)) return false;
  *out = in.cast<float>();
  return true;
}

// ---------------------------------------------------------------------------------------------
// PLY header

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };
enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };

bool parsePlyType(absl::string_view name, PlyType* type) {
  static const std::pair<const char*, PlyType> kNames[] = {
      {"char", PlyType::kInt8},      {"int8", PlyType::kInt8},       {"uchar", PlyType::kUint8},
      {"uint8", PlyType::kUint8},    {"short", PlyType::kInt16},     {"int16", PlyType::kInt16},
      {"ushort", PlyType::kUint16},  {"uint16", PlyType::kUint16},   {"int", PlyType::kInt32},
      {"int32", PlyType::kInt32},    {"uint", PlyType::kUint32},     {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32},  {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64},
      {"float64", PlyType::kFloat64}};
  for (const auto& [n, t] : kNames) {
    if (name == n) {
      *type = t;
      return true;
    }
  }
  return false;
}

size_t typeSize(PlyType type) {
  switch (type) {
    case PlyType::kInt8:
    case PlyType::kUint8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUint16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 1;
}

bool isIntegerType(PlyType type) { return type != PlyType::kFloat32 && type != PlyType::kFloat64; }

void integerRange(PlyType type, double* lo, double* hi) {
  switch (type) {
    case PlyType::kInt8:
      *lo = -128;
      *hi = 127;
      return;
    case PlyType::kUint8:
      *lo = 0;
      *hi = 255;
      return;
    case PlyType::kInt16:
      *lo = -32768;
      *hi = 32767;
      return;
    case PlyType::kUint16:
      *lo = 0;
      *hi = 65535;
      return;
    case PlyType::kInt32:
      *lo = -2147483648.0;
      *hi = 2147483647.0;
      return;
    case PlyType::kUint32:
      *lo = 0;
      *hi = 4294967295.0;
      return;
    default:
      *lo = -HUGE_VAL;
      *hi = HUGE_VAL;
      return;
  }
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;  // item type for lists
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;
  // Fewest bytes one instance can take in a binary file (lists with zero items).
  uint64_t minBinaryBytes() const {
    uint64_t bytes = 0;
    for (const auto& p : properties) bytes += typeSize(p.is_list ? p.count_type : p.type);
    return bytes;
  }
  int find(absl::string_view property) const {
    for (size_t i = 0; i < properties.size(); ++i) {
      if (properties[i].name == property) return static_cast<int>(i);
    }
    return -1;
  }
};

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  size_t data_offset = 0;  // first byte after "end_header\n"
  size_t lines = 0;        // header lines, for ASCII line numbers
};

StatusOr<PlyHeader> parsePlyHeader(absl::string_view text, const std::string& file) {
  LineReader lines(text, file);
  absl::string_view line;
  if (!lines.next(&line) || line != "ply") {
    OBJDB_RETURN_IF_ERROR(lines.status());
    return absl::InvalidArgumentError(absl::StrCat(file, " is not a PLY file (no 'ply' line)"));
  }
  PlyHeader header;
  bool have_format = false;
  while (true) {
    if (!lines.next(&line)) {
      OBJDB_RETURN_IF_ERROR(lines.status());
      return absl::InvalidArgumentError(absl::StrCat(file, ": PLY header has no end_header line"));
    }
    if (lines.lineNumber() > 100000) return lines.error("PLY header is longer than 100000 lines");
    const auto fields = internal::splitFields(line);
    if (fields.empty()) continue;
    const absl::string_view keyword = fields[0];
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "end_header") break;
    if (keyword == "format") {
      if (fields.size() != 3 || fields[2] != "1.0") {
        return lines.error("expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0'");
      }
      if (fields[1] == "ascii") {
        header.format = PlyFormat::kAscii;
      } else if (fields[1] == "binary_little_endian") {
        header.format = PlyFormat::kBinaryLittleEndian;
      } else if (fields[1] == "binary_big_endian") {
        header.format = PlyFormat::kBinaryBigEndian;
      } else {
        return lines.error(absl::StrCat("unknown PLY format '", fields[1], "'"));
      }
      have_format = true;
    } else if (keyword == "element") {
      PlyElement element;
      if (fields.size() != 3 || !internal::parseUint64(fields[2], &element.count)) {
        return lines.error("expected 'element <name> <count>' with a non-negative count");
      }
      element.name = std::string(fields[1]);
      header.elements.push_back(std::move(element));
    } else if (keyword == "property") {
      if (header.elements.empty()) return lines.error("property before any element");
      PlyProperty property;
      if (fields.size() == 5 && fields[1] == "list") {
        property.is_list = true;
        if (!parsePlyType(fields[2], &property.count_type) || !isIntegerType(property.count_type)) {
          return lines.error(
              absl::StrCat("list count type '", fields[2], "' is not an integer PLY type"));
        }
        if (!parsePlyType(fields[3], &property.type)) {
          return lines.error(absl::StrCat("unknown PLY type '", fields[3], "'"));
        }
        property.name = std::string(fields[4]);
      } else if (fields.size() == 3) {
        if (!parsePlyType(fields[1], &property.type)) {
          return lines.error(absl::StrCat("unknown PLY type '", fields[1], "'"));
        }
        property.name = std::string(fields[2]);
      } else {
        return lines.error(
            "expected 'property <type> <name>' or 'property list <count type> <type> <name>'");
      }
      header.elements.back().properties.push_back(std::move(property));
    } else {
      return lines.error(absl::StrCat("unknown PLY header keyword '", keyword, "'"));
    }
  }
  if (!have_format) {
    return absl::InvalidArgumentError(absl::StrCat(file, ": PLY header has no format line"));
  }
  header.data_offset = lines.offset();
  header.lines = lines.lineNumber();
  return header;
}

// ---------------------------------------------------------------------------------------------
// PLY bodies. Both sources read one scalar at a time as a double (exact for every PLY type) and
// describe where they are for error messages.

class AsciiSource {
 public:
  AsciiSource(absl::string_view text, size_t offset, size_t header_lines, std::string file)
      : text_(text), pos_(offset), line_(header_lines + 1), file_(std::move(file)) {}

  uint64_t remainingBytes() const { return text_.size() - pos_; }

  Status read(PlyType type, double* value) {
    const char* data = text_.data();
    while (pos_ < text_.size() && isSpace(data[pos_])) {
      if (data[pos_] == '\n') ++line_;
      ++pos_;
    }
    token_line_ = line_;
    if (pos_ >= text_.size()) return absl::InvalidArgumentError("unexpected end of file");
    const size_t start = pos_;
    while (pos_ < text_.size() && !isSpace(data[pos_])) ++pos_;
    const absl::string_view token = text_.substr(start, pos_ - start);
    if (!internal::parseDouble(token, value)) {
      return absl::InvalidArgumentError(absl::StrCat("'", token, "' is not a number"));
    }
    if (isIntegerType(type)) {
      double lo, hi;
      integerRange(type, &lo, &hi);
      if (!(*value == std::floor(*value) && *value >= lo && *value <= hi)) {
        return absl::InvalidArgumentError(
            absl::StrCat("'", token, "' is not a valid value of the property's integer type"));
      }
    }
    return absl::OkStatus();
  }

  Status error(const PlyElement& element, uint64_t index, absl::string_view property,
               absl::string_view message) const {
    return absl::InvalidArgumentError(absl::StrFormat("%s line %d: element '%s' %d%s: %s", file_,
                                                      token_line_, element.name, index,
                                                      propertySuffix(property), message));
  }

 private:
  static bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }
  static std::string propertySuffix(absl::string_view property) {
    return property.empty() ? std::string() : absl::StrCat(", property '", property, "'");
  }
  absl::string_view text_;
  size_t pos_;
  size_t line_;
  size_t token_line_ = 0;
  std::string file_;
};

class BinarySource {
 public:
  BinarySource(absl::string_view data, size_t offset, bool big_endian, std::string file)
      : data_(data),
        pos_(offset),
        swap_(big_endian != (std::endian::native == std::endian::big)),
        file_(std::move(file)) {}

  uint64_t remainingBytes() const { return data_.size() - pos_; }

  Status read(PlyType type, double* value) {
    const size_t size = typeSize(type);
    if (!(size <= data_.size() - pos_)) {
      return absl::InvalidArgumentError("unexpected end of file (truncated binary data)");
    }
    unsigned char bytes[8];
    std::memcpy(bytes, data_.data() + pos_, size);
    pos_ += size;
    if (swap_) std::reverse(bytes, bytes + size);
    switch (type) {
      case PlyType::kInt8:
        *value = load<int8_t>(bytes);
        break;
      case PlyType::kUint8:
        *value = load<uint8_t>(bytes);
        break;
      case PlyType::kInt16:
        *value = load<int16_t>(bytes);
        break;
      case PlyType::kUint16:
        *value = load<uint16_t>(bytes);
        break;
      case PlyType::kInt32:
        *value = load<int32_t>(bytes);
        break;
      case PlyType::kUint32:
        *value = load<uint32_t>(bytes);
        break;
      case PlyType::kFloat32:
        *value = load<float>(bytes);
        break;
      case PlyType::kFloat64:
        *value = load<double>(bytes);
        break;
    }
    return absl::OkStatus();
  }

  Status error(const PlyElement& element, uint64_t index, absl::string_view property,
               absl::string_view message) const {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: element '%s' %d%s: %s", file_, element.name, index,
        property.empty() ? std::string() : absl::StrCat(", property '", property, "'"), message));
  }

 private:
  template <typename T>
  static double load(const unsigned char* bytes) {
    T v;
    std::memcpy(&v, bytes, sizeof(T));
    return static_cast<double>(v);
  }
  absl::string_view data_;
  size_t pos_;
  bool swap_;
  std::string file_;
};

// Checks that `element.count` instances can fit in what is left of the file before anything is
// allocated for them.
template <typename Source>
Status checkCountFits(const PlyElement& element, const Source& source, bool binary,
                      const std::string& file) {
  const uint64_t remaining = source.remainingBytes();
  // ASCII: every value is at least one character plus a separator.
  const uint64_t per_instance =
      binary ? element.minBinaryBytes() : 2 * uint64_t(element.properties.size());
  if (per_instance == 0) return absl::OkStatus();
  if (element.count <= (remaining + 1) / per_instance) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrFormat(
      "%s: header declares %d '%s' elements of at least %d bytes each, but only %d bytes of data "
      "follow the header",
      file, element.count, element.name, per_instance, remaining));
}

struct VertexLayout {
  int x = -1, y = -1, z = -1, nx = -1, ny = -1, nz = -1, red = -1, green = -1, blue = -1;
};

template <typename Source>
Status readPlyBody(const PlyHeader& header, Source& source, const std::string& file,
                   TriangleMesh* mesh) {
  const bool binary = header.format != PlyFormat::kAscii;
  const PlyElement* vertex_element = nullptr;
  for (const auto& element : header.elements) {
    if (element.name == "vertex") vertex_element = &element;
  }
  if (!vertex_element) {
    return absl::InvalidArgumentError(absl::StrCat(file, ": PLY file has no 'vertex' element"));
  }
  if (!(vertex_element->count <= kMaxVertices)) {
    return absl::InvalidArgumentError(absl::StrFormat("%s: %d vertices exceed the limit of %d",
                                                      file, vertex_element->count, kMaxVertices));
  }
  const uint64_t vertex_count = vertex_element->count;
  std::vector<double> values;
  std::vector<double> face_indices;
  for (const auto& element : header.elements) {
    if (element.properties.empty()) continue;  // takes no bytes
    OBJDB_RETURN_IF_ERROR(checkCountFits(element, source, binary, file));
    const bool is_vertex = &element == vertex_element;
    const bool is_face = element.name == "face";
    VertexLayout layout;
    int index_property = -1;
    if (is_vertex) {
      const auto scalar = [&](const char* name) {
        const int i = element.find(name);
        return i >= 0 && !element.properties[size_t(i)].is_list ? i : -1;
      };
      layout = {scalar("x"),  scalar("y"),   scalar("z"),     scalar("nx"),  scalar("ny"),
                scalar("nz"), scalar("red"), scalar("green"), scalar("blue")};
      if (layout.x < 0 || layout.y < 0 || layout.z < 0) {
        return absl::InvalidArgumentError(
            absl::StrCat(file, ": element 'vertex' lacks one of the scalar properties x, y, z"));
      }
      mesh->vertices.reserve(element.count);
      if (layout.nx >= 0 && layout.ny >= 0 && layout.nz >= 0) mesh->normals.reserve(element.count);
      if (layout.red >= 0 && layout.green >= 0 && layout.blue >= 0) {
        mesh->colors.reserve(element.count);
      }
    } else if (is_face) {
      index_property = element.find("vertex_indices");
      if (index_property < 0) index_property = element.find("vertex_index");
      if (index_property < 0 || !element.properties[size_t(index_property)].is_list ||
          !isIntegerType(element.properties[size_t(index_property)].type)) {
        return absl::InvalidArgumentError(
            absl::StrCat(file, ": element 'face' has no integer list property 'vertex_indices'"));
      }
      // A usable face takes at least 4 bytes (binary: count + 3 one-byte indices; ASCII: "3 0 1 2"
      // takes 7), so this never reserves more than a few times the file size.
      mesh->triangles.reserve(mesh->triangles.size() +
                              std::min<uint64_t>(element.count, source.remainingBytes() / 4));
    }
    const bool has_normals = is_vertex && layout.nx >= 0 && layout.ny >= 0 && layout.nz >= 0;
    const bool has_colors = is_vertex && layout.red >= 0 && layout.green >= 0 && layout.blue >= 0;
    values.assign(element.properties.size(), 0.0);

    for (uint64_t n = 0; n < element.count; ++n) {
      for (size_t p = 0; p < element.properties.size(); ++p) {
        const PlyProperty& property = element.properties[p];
        if (!property.is_list) {
          const Status s = source.read(property.type, &values[p]);
          if (!s.ok()) return source.error(element, n, property.name, s.message());
          continue;
        }
        double count_value = 0.0;
        Status s = source.read(property.count_type, &count_value);
        if (!s.ok()) return source.error(element, n, property.name, s.message());
        if (!(count_value >= 0.0)) {
          return source.error(element, n, property.name,
                              absl::StrFormat("negative list length %g", count_value));
        }
        const uint64_t count = static_cast<uint64_t>(count_value);
        const uint64_t min_item_bytes = binary ? typeSize(property.type) : 2;
        if (!(count <= (source.remainingBytes() + 1) / min_item_bytes)) {
          return source.error(element, n, property.name,
                              absl::StrFormat("list of %d items runs past the end of file", count));
        }
        const bool keep = is_face && int(p) == index_property;
        if (keep) face_indices.clear();
        for (uint64_t k = 0; k < count; ++k) {
          double item = 0.0;
          s = source.read(property.type, &item);
          if (!s.ok()) return source.error(element, n, property.name, s.message());
          if (keep) face_indices.push_back(item);
        }
      }
      if (is_vertex) {
        const Eigen::Vector3d p(values[size_t(layout.x)], values[size_t(layout.y)],
                                values[size_t(layout.z)]);
        Eigen::Vector3f pf;
        if (!toFiniteFloats(p, &pf)) {
          return source.error(
              element, n, "",
              absl::StrFormat("position (%g, %g, %g) is not finite in float", p.x(), p.y(), p.z()));
        }
        mesh->vertices.push_back(pf);
        if (has_normals) {
          Eigen::Vector3f normal;
          if (!toFiniteFloats(Eigen::Vector3d(values[size_t(layout.nx)], values[size_t(layout.ny)],
                                              values[size_t(layout.nz)]),
                              &normal)) {
            return source.error(element, n, "", "normal is not finite");
          }
          mesh->normals.push_back(normal);
        }
        if (has_colors) {
          uint8_t rgb[3];
          const int indices[3] = {layout.red, layout.green, layout.blue};
          for (int c = 0; c < 3; ++c) {
            const PlyProperty& property = element.properties[size_t(indices[c])];
            const double v = values[size_t(indices[c])];
            if (isIntegerType(property.type)) {
              if (!(v >= 0.0 && v <= 255.0)) {
                return source.error(element, n, property.name,
                                    absl::StrFormat("colour %g is outside 0..255", v));
              }
              rgb[c] = static_cast<uint8_t>(v);
            } else {
              if (!(v >= 0.0 && v <= 1.0)) {
                return source.error(element, n, property.name,
                                    absl::StrFormat("colour %g is outside 0..1", v));
              }
              rgb[c] = static_cast<uint8_t>(std::lround(v * 255.0));
            }
          }
          mesh->colors.push_back({rgb[0], rgb[1], rgb[2]});
        }
      } else if (is_face) {
        const std::string& name = element.properties[size_t(index_property)].name;
        if (face_indices.size() < 3) {
          return source.error(
              element, n, name,
              absl::StrFormat("face has %d vertices; at least 3 are needed", face_indices.size()));
        }
        for (double index : face_indices) {
          if (!(index >= 0.0 && index < double(vertex_count))) {
            return source.error(element, n, name,
                                absl::StrFormat("vertex index %g is outside 0..%d", index,
                                                int64_t(vertex_count) - 1));
          }
        }
        for (size_t k = 1; k + 1 < face_indices.size(); ++k) {
          mesh->triangles.emplace_back(int(face_indices[0]), int(face_indices[k]),
                                       int(face_indices[k + 1]));
        }
      }
    }
  }
  return absl::OkStatus();
}

StatusOr<TriangleMesh> readPly(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string data, internal::readFile(path));
  const std::string file = path.string();
  OBJDB_ASSIGN_OR_RETURN(const PlyHeader header, parsePlyHeader(data, file));
  TriangleMesh mesh;
  if (header.format == PlyFormat::kAscii) {
    AsciiSource source(data, header.data_offset, header.lines, file);
    OBJDB_RETURN_IF_ERROR(readPlyBody(header, source, file, &mesh));
  } else {
    BinarySource source(data, header.data_offset, header.format == PlyFormat::kBinaryBigEndian,
                        file);
    OBJDB_RETURN_IF_ERROR(readPlyBody(header, source, file, &mesh));
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// OBJ

// Resolves a 1-based (or negative, relative) OBJ index against `count` elements seen so far.
// Positive indices may refer forward; they are range-checked once the whole file is read.
bool resolveObjIndex(absl::string_view token, int64_t count, int64_t* index) {
  int64_t value = 0;
  if (!internal::parseInt64(token, &value) || value == 0) return false;
  *index = value > 0 ? value - 1 : count + value;
  return *index >= 0;
}

StatusOr<TriangleMesh> readObj(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string text, internal::readFile(path));
  LineReader lines(text, path.string());
  TriangleMesh mesh;
  int64_t max_index = -1;
  size_t max_index_line = 0;
  std::vector<int> corners;
  absl::string_view line;
  while (lines.next(&line)) {
    if (internal::isCommentOrBlank(line)) continue;
    const auto fields = internal::splitFields(line);
    const absl::string_view keyword = fields[0];
    if (keyword == "v") {
      if (fields.size() < 4) return lines.error("vertex needs x y z");
      Eigen::Vector3d p;
      for (int k = 0; k < 3; ++k) {
        if (!internal::parseDouble(fields[size_t(k) + 1], &p[k])) {
          return lines.error(
              absl::StrCat("vertex coordinate '", fields[size_t(k) + 1], "' is not a number"));
        }
      }
      Eigen::Vector3f pf;
      if (!toFiniteFloats(p, &pf)) return lines.error("vertex is not finite");
      if (!(mesh.vertices.size() < kMaxVertices)) return lines.error("too many vertices");
      mesh.vertices.push_back(pf);
    } else if (keyword == "f") {
      if (fields.size() < 4) {
        return lines.error(
            absl::StrFormat("face has %d vertices; at least 3 are needed", fields.size() - 1));
      }
      corners.clear();
      const int64_t count = static_cast<int64_t>(mesh.vertices.size());
      for (size_t k = 1; k < fields.size(); ++k) {
        const absl::string_view corner = fields[k];
        const size_t slash = corner.find('/');
        const absl::string_view v_token = corner.substr(0, slash);
        int64_t index = 0;
        if (!resolveObjIndex(v_token, count, &index)) {
          return lines.error(absl::StrFormat(
              "face vertex '%s' is not a valid index (1-based, or negative from the last of the "
              "%d vertices so far)",
              corner, count));
        }
        if (slash != absl::string_view::npos) {
          // v/vt, v//vn or v/vt/vn: texture and normal indices are checked but not kept.
          const absl::string_view rest = corner.substr(slash + 1);
          const size_t slash2 = rest.find('/');
          const absl::string_view vt = rest.substr(0, slash2);
          const absl::string_view vn =
              slash2 == absl::string_view::npos ? absl::string_view() : rest.substr(slash2 + 1);
          int64_t ignored = 0;
          if ((!vt.empty() && !internal::parseInt64(vt, &ignored)) ||
              (slash2 != absl::string_view::npos && !internal::parseInt64(vn, &ignored)) ||
              vn.find('/') != absl::string_view::npos) {
            return lines.error(absl::StrCat("face vertex '", corner,
                                            "' is not of the form v, v/vt, v//vn or v/vt/vn"));
          }
        }
        if (!(index < int64_t(kMaxVertices))) return lines.error("face index too large");
        if (index > max_index) {
          max_index = index;
          max_index_line = lines.lineNumber();
        }
        corners.push_back(static_cast<int>(index));
      }
      for (size_t k = 1; k + 1 < corners.size(); ++k) {
        mesh.triangles.emplace_back(corners[0], corners[k], corners[k + 1]);
      }
    }
    // vt, vn, g, o, s, usemtl, mtllib, l, p, ...: not part of a triangle mesh.
  }
  OBJDB_RETURN_IF_ERROR(lines.status());
  if (max_index >= int64_t(mesh.vertices.size())) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s line %d: face refers to vertex %d but the file has only %d vertices",
                        path.string(), max_index_line, max_index + 1, mesh.vertices.size()));
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// STL

// Identical corners of neighbouring facets become one vertex.
class VertexMerger {
 public:
  explicit VertexMerger(TriangleMesh* mesh) : mesh_(mesh) {}
  int add(const Eigen::Vector3f& p) {
    Key key;
    for (int k = 0; k < 3; ++k) {
      const float v = p[k] + 0.0f;  // -0 → +0
      std::memcpy(&key[size_t(k)], &v, sizeof(float));
    }
    const auto [it, inserted] = index_.try_emplace(key, int(mesh_->vertices.size()));
    if (inserted) mesh_->vertices.push_back(p);
    return it->second;
  }

 private:
  using Key = std::array<uint32_t, 3>;
  struct KeyHash {
    size_t operator()(const Key& k) const {
      uint64_t h = 1469598103934665603ull;
      for (uint32_t v : k) h = (h ^ v) * 1099511628211ull;
      return size_t(h);
    }
  };
  TriangleMesh* mesh_;
  std::unordered_map<Key, int, KeyHash> index_;
};

StatusOr<TriangleMesh> readBinaryStl(absl::string_view data, const std::string& file) {
  if (data.size() < 84) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: %d bytes is too short for a binary STL (80-byte header and triangle count)", file,
        data.size()));
  }
  uint32_t count = 0;
  std::memcpy(&count, data.data() + 80, 4);
  if constexpr (std::endian::native == std::endian::big) {
    count =
        ((count & 0xFF) << 24) | ((count & 0xFF00) << 8) | ((count >> 8) & 0xFF00) | (count >> 24);
  }
  const uint64_t expected = 84 + 50 * uint64_t(count);
  if (expected != data.size()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: binary STL header declares %d triangles (%d bytes) but the file has %d bytes", file,
        count, expected, data.size()));
  }
  TriangleMesh mesh;
  mesh.triangles.reserve(count);
  VertexMerger merger(&mesh);
  for (uint32_t i = 0; i < count; ++i) {
    const char* record = data.data() + 84 + 50 * size_t(i);
    Eigen::Vector3i triangle;
    for (int c = 0; c < 3; ++c) {
      Eigen::Vector3f p;
      for (int k = 0; k < 3; ++k) {
        unsigned char bytes[4];
        std::memcpy(bytes, record + 12 + 12 * c + 4 * k, 4);
        if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + 4);
        std::memcpy(&p[k], bytes, 4);
      }
      if (!p.allFinite()) {
        return absl::InvalidArgumentError(
            absl::StrFormat("%s: triangle %d corner %d is not finite", file, i, c));
      }
      triangle[c] = merger.add(p);
    }
    mesh.triangles.push_back(triangle);
  }
  return mesh;
}

StatusOr<TriangleMesh> readAsciiStl(absl::string_view text, const std::string& file) {
  LineReader lines(text, file);
  TriangleMesh mesh;
  VertexMerger merger(&mesh);
  enum class State { kOutside, kSolid, kFacet, kLoop, kEndLoop };
  State state = State::kOutside;
  std::vector<int> corners;
  absl::string_view line;
  while (lines.next(&line)) {
    const auto fields = internal::splitFields(line);
    if (fields.empty()) continue;
    const std::string keyword = internal::toLower(fields[0]);
    const auto unexpected = [&]() {
      return lines.error(absl::StrCat("unexpected '", fields[0], "' in ASCII STL"));
    };
    switch (state) {
      case State::kOutside:
        if (keyword != "solid") return unexpected();
        state = State::kSolid;
        break;
      case State::kSolid:
        if (keyword == "endsolid") {
          state = State::kOutside;
        } else if (keyword == "facet") {
          state = State::kFacet;
        } else {
          return unexpected();
        }
        break;
      case State::kFacet:
        if (keyword != "outer") return unexpected();
        corners.clear();
        state = State::kLoop;
        break;
      case State::kLoop:
        if (keyword == "vertex") {
          if (fields.size() != 4) return lines.error("expected 'vertex x y z'");
          Eigen::Vector3d p;
          for (int k = 0; k < 3; ++k) {
            if (!internal::parseDouble(fields[size_t(k) + 1], &p[k])) {
              return lines.error(
                  absl::StrCat("vertex coordinate '", fields[size_t(k) + 1], "' is not a number"));
            }
          }
          Eigen::Vector3f pf;
          if (!toFiniteFloats(p, &pf)) return lines.error("vertex is not finite");
          corners.push_back(merger.add(pf));
        } else if (keyword == "endloop") {
          if (corners.size() < 3) {
            return lines.error(
                absl::StrFormat("facet has %d vertices; at least 3 are needed", corners.size()));
          }
          for (size_t k = 1; k + 1 < corners.size(); ++k) {
            mesh.triangles.emplace_back(corners[0], corners[k], corners[k + 1]);
          }
          state = State::kEndLoop;
        } else {
          return unexpected();
        }
        break;
      case State::kEndLoop:
        if (keyword != "endfacet") return unexpected();
        state = State::kSolid;
        break;
    }
  }
  OBJDB_RETURN_IF_ERROR(lines.status());
  if (state != State::kOutside) {
    return lines.error("ASCII STL ends inside a solid (missing endsolid)");
  }
  return mesh;
}

StatusOr<TriangleMesh> readStl(const fs::path& path) {
  OBJDB_ASSIGN_OR_RETURN(const std::string data, internal::readFile(path));
  const std::string file = path.string();
  // Binary files may also begin with "solid": the size check of the binary layout decides.
  bool binary_size_matches = false;
  if (data.size() >= 84) {
    uint32_t count = 0;
    std::memcpy(&count, data.data() + 80, 4);
    if constexpr (std::endian::native == std::endian::big) {
      count = ((count & 0xFF) << 24) | ((count & 0xFF00) << 8) | ((count >> 8) & 0xFF00) |
              (count >> 24);
    }
    binary_size_matches = 84 + 50 * uint64_t(count) == data.size();
  }
  const size_t first = data.find_first_not_of(" \t\r\n");
  const bool starts_with_solid =
      first != std::string::npos && internal::toLower(data.substr(first, 5)) == "solid";
  if (starts_with_solid && !binary_size_matches) return readAsciiStl(data, file);
  return readBinaryStl(data, file);
}

// ---------------------------------------------------------------------------------------------
// PLY writing

std::string formatFloat(float value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

template <typename T>
void appendLittleEndian(std::string* out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(bytes, bytes + sizeof(T));
  out->append(bytes, sizeof(T));
}

std::string plyBytes(const std::vector<Eigen::Vector3f>& points,
                     const std::vector<Eigen::Vector3f>& normals, const std::vector<Rgb8>& colors,
                     const std::vector<Eigen::Vector3i>* triangles, bool ascii) {
  const bool has_normals = !normals.empty();
  const bool has_colors = !colors.empty();
  std::string out = "ply\n";
  absl::StrAppend(&out, "format ", ascii ? "ascii" : "binary_little_endian", " 1.0\n",
                  "comment written by objdb\n", "element vertex ", points.size(), "\n",
                  "property float x\nproperty float y\nproperty float z\n");
  if (has_normals) out += "property float nx\nproperty float ny\nproperty float nz\n";
  if (has_colors) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (triangles) {
    absl::StrAppend(&out, "element face ", triangles->size(), "\n",
                    "property list uchar int vertex_indices\n");
  }
  out += "end_header\n";
  for (size_t i = 0; i < points.size(); ++i) {
    if (ascii) {
      const auto& p = points[i];
      absl::StrAppend(&out, formatFloat(p.x()), " ", formatFloat(p.y()), " ", formatFloat(p.z()));
      if (has_normals) {
        const auto& n = normals[i];
        absl::StrAppend(&out, " ", formatFloat(n.x()), " ", formatFloat(n.y()), " ",
                        formatFloat(n.z()));
      }
      if (has_colors) {
        absl::StrAppend(&out, " ", int(colors[i].r), " ", int(colors[i].g), " ", int(colors[i].b));
      }
      out += '\n';
    } else {
      for (int k = 0; k < 3; ++k) appendLittleEndian(&out, points[i][k]);
      if (has_normals) {
        for (int k = 0; k < 3; ++k) appendLittleEndian(&out, normals[i][k]);
      }
      if (has_colors) {
        out += static_cast<char>(colors[i].r);
        out += static_cast<char>(colors[i].g);
        out += static_cast<char>(colors[i].b);
      }
    }
  }
  if (triangles) {
    for (const auto& t : *triangles) {
      if (ascii) {
        absl::StrAppend(&out, "3 ", t[0], " ", t[1], " ", t[2], "\n");
      } else {
        out += static_cast<char>(3);
        for (int k = 0; k < 3; ++k) appendLittleEndian<int32_t>(&out, t[k]);
      }
    }
  }
  return out;
}

// `what`: "cannot write <file>" or the like, the start of every error.
Status checkAttributes(const std::string& what, const std::vector<Eigen::Vector3f>& points,
                       const std::vector<Eigen::Vector3f>& normals,
                       const std::vector<Rgb8>& colors) {
  if (!(normals.empty() || normals.size() == points.size())) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: %d normals for %d points", what, normals.size(), points.size()));
  }
  if (!(colors.empty() || colors.size() == points.size())) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: %d colours for %d points", what, colors.size(), points.size()));
  }
  if (!(points.size() <= kMaxVertices)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: too many points (%d)", what, points.size()));
  }
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) {
      return absl::InvalidArgumentError(absl::StrFormat("%s: point %d is not finite", what, i));
    }
  }
  for (size_t i = 0; i < normals.size(); ++i) {
    if (!normals[i].allFinite()) {
      return absl::InvalidArgumentError(absl::StrFormat("%s: normal %d is not finite", what, i));
    }
  }
  return absl::OkStatus();
}

}  // namespace

StatusOr<TriangleMesh> readMesh(const fs::path& path) {
  const std::string extension = internal::toLower(path.extension().string());
  StatusOr<TriangleMesh> mesh;
  try {
    if (extension == ".ply") {
      mesh = readPly(path);
    } else if (extension == ".obj") {
      mesh = readObj(path);
    } else if (extension == ".stl") {
      mesh = readStl(path);
    } else {
      return absl::InvalidArgumentError(
          absl::StrCat("cannot read mesh ", path.string(), ": unknown extension '",
                       path.extension().string(), "' (expected .ply, .obj or .stl)"));
    }
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(
        absl::StrCat("out of memory while reading mesh ", path.string()));
  }
  if (!mesh.ok()) return mesh.status();
  OBJDB_RETURN_IF_ERROR(annotate(mesh->validate(), path.string()));
  return mesh;
}

StatusOr<std::string> plyMeshBytes(const TriangleMesh& mesh, bool ascii,
                                   const std::string& what) {
  OBJDB_RETURN_IF_ERROR(annotate(mesh.validate(), what));
  OBJDB_RETURN_IF_ERROR(checkAttributes(what, mesh.vertices, mesh.normals, mesh.colors));
  try {
    return plyBytes(mesh.vertices, mesh.normals, mesh.colors, &mesh.triangles, ascii);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(absl::StrCat(what, ": out of memory"));
  }
}

StatusOr<std::string> plyCloudBytes(const PointCloud& cloud, bool ascii,
                                    const std::string& what) {
  OBJDB_RETURN_IF_ERROR(checkAttributes(what, cloud.points, cloud.normals, cloud.colors));
  try {
    return plyBytes(cloud.points, cloud.normals, cloud.colors, nullptr, ascii);
  } catch (const std::bad_alloc&) {
    return absl::ResourceExhaustedError(absl::StrCat(what, ": out of memory"));
  }
}

Status writePlyMesh(const fs::path& path, const TriangleMesh& mesh, bool ascii) {
  OBJDB_ASSIGN_OR_RETURN(const std::string bytes,
                         plyMeshBytes(mesh, ascii, absl::StrCat("cannot write ", path.string())));
  return internal::writeFileAtomic(path, bytes);
}

Status writePlyCloud(const fs::path& path, const PointCloud& cloud, bool ascii) {
  OBJDB_ASSIGN_OR_RETURN(const std::string bytes,
                         plyCloudBytes(cloud, ascii, absl::StrCat("cannot write ", path.string())));
  return internal::writeFileAtomic(path, bytes);
}

}  // namespace objdb::io
