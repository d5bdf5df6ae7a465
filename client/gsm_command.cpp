// `objdb gsm`: runs depth segmentation and the Global Segmentation Map over a dataset, writes the
// map's surface coloured by global label and, optionally, every extracted raw segment as a mesh.
#include <cstdio>
#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

#include "client/cli_util.h"
#include "client/commands.h"
#include "client/frame_loop.h"
#include "core/gsm/gsm.h"
#include "core/io/dataset.h"
#include "core/io/mesh_io.h"
#include "core/segmentation/depth_segmenter.h"
#include "core/tsdf/mesh_extraction.h"

namespace objdb {
namespace {

constexpr const char* kUsage = R"(usage: objdb gsm --dataset DIR --out MESH.ply [options]

Segments every frame of a dataset (objdb or TUM layout), fuses the segments into a Global
Segmentation Map (TSDF + per-voxel label history) and writes the map's surface coloured by
global label. Labels that stop changing are extracted as raw segments, as the object database
will receive them; at the end every remaining label is flushed.

  --dataset DIR       dataset folder
  --out FILE          output mesh (.ply), vertex colour = global label
  --segments-out DIR  also write every raw segment's surface as DIR/segment_<label>.ply
  --config FILE       parameters as JSON ("segmentation", "tsdf", "gsm" sections apply)
  --every N           use every N-th frame (default 1)
  --threads N         TSDF integration threads (default 2)
)";

int usageError(const std::string& message) { return cli::usageError("gsm", message, kUsage); }
int reportError(const Status& status) { return cli::reportError("gsm", status); }

Rgb8 labelColor(gsm::Label label) {
  if (label == 0) return {128, 128, 128};
  const uint32_t h = label * 2654435761u;
  return {uint8_t(64 + (h & 0xbf)), uint8_t(64 + ((h >> 8) & 0xbf)), uint8_t(64 + ((h >> 16) & 0xbf))};
}

}  // namespace

int runGsmCommand(int argc, char** argv) {
  cli::DatasetJobOptions job;
  std::string segments_out;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "-h" || a == "--help") {
      std::printf("%s", kUsage);
      return 0;
    }
    if (i + 1 >= argc) return usageError(a.rfind("--", 0) == 0 ? a + " needs a value" : "unexpected argument '" + a + "'");
    const char* value = argv[++i];
    std::string error;
    if (cli::parseDatasetJobOption(a, value, &job, &error)) {
      if (!error.empty()) return usageError(error);
    } else if (a == "--segments-out") {
      segments_out = value;
    } else {
      return usageError("unknown option '" + a + "'");
    }
  }
  if (job.dataset.empty() || job.out.empty()) return usageError("--dataset and --out are required");
  auto loaded = cli::loadParams(job.config);
  if (!loaded.ok()) return reportError(loaded.status());
  const Params params = *loaded;
  auto opened = io::openDataset(job.dataset);
  if (!opened.ok()) return reportError(opened.status());
  const io::Dataset& ds = **opened;
  auto segmenter = segmentation::DepthSegmenter::create(params.segmentation, ds.intrinsics());
  if (!segmenter.ok()) return reportError(segmenter.status());
  auto map = gsm::Gsm::create(params.tsdf, params.gsm, ds.intrinsics(), int(job.threads));
  if (!map.ok()) return reportError(map.status());
  if (!segments_out.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(segments_out, ec);
    if (ec) return reportError(absl::UnavailableError("cannot create " + segments_out + ": " + ec.message()));
  }

  size_t extracted = 0;
  auto write_segments = [&](std::vector<gsm::RawSegment> segments,
                            std::vector<gsm::Label> /*withdrawn: files already written stay*/) -> Status {
    for (auto& segment : segments) {
      ++extracted;
      if (segments_out.empty()) continue;
      tsdf::MeshLayer meshes(params.tsdf.mesh_min_weight);
      meshes.update(&segment.grid, true);
      TriangleMesh mesh = meshes.mesh();
      mesh.transform(segment.T_world_segment);  // written in world coordinates
      const auto path = std::filesystem::path(segments_out) /
                        ("segment_" + std::to_string(segment.label) + ".ply");
      OBJDB_RETURN_IF_ERROR(io::writePlyMesh(path, mesh));
    }
    return absl::OkStatus();
  };
  auto looped = cli::segmentAndFuse(ds, &*segmenter, &*map, size_t(job.every), "gsm",
                                    "segmenting + fusing", write_segments);
  if (!looped.ok()) return reportError(looped.status());
  const size_t used = looped->used, rejected = looped->rejected, merges = looped->merges;
  const double seg_ms = looped->segmentation_ms, gsm_ms = looped->fusion_ms;

  tsdf::MeshLayer meshes(params.tsdf.mesh_min_weight);
  meshes.update(&map->tsdf(), true);
  TriangleMesh mesh = meshes.mesh();
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    mesh.colors[v] = labelColor(map->mainLabel(map->tsdf().voxelIndexOf(mesh.vertices[v])));
  }
  if (Status s = io::writePlyMesh(job.out, mesh); !s.ok()) return reportError(s);
  std::printf("%zu frames (%zu skipped); segmentation %.1f ms/frame, TSDF %.1f ms/frame\n", used,
              rejected, used ? seg_ms / double(used) : 0.0, used ? gsm_ms / double(used) : 0.0);
  std::printf("%zu labels, %zu merges, %zu raw segments extracted; %.1f MB TSDF + %.1f MB labels\n",
              map->numLabels(), merges, extracted, double(map->tsdf().voxelBytes()) / 1e6,
              double(map->labelBytes()) / 1e6);
  std::printf("mesh coloured by label: %zu vertices, %zu triangles -> %s\n", mesh.vertices.size(),
              mesh.triangles.size(), job.out.c_str());
  // What the grouping made of the map at its end (docs/structure.md).
  const gsm::ObjectGroups groups = map->groupObjects();
  size_t objects = 0;
  for (const auto& [id, members] : groups.members) objects += groups.structure.contains(id) ? 0 : 1;
  std::printf("room structure: %s\n", groups.room.summary().c_str());
  std::printf("objects: %zu of %zu labels (%zu structure labels, %zu of them larger than furniture); "
              "%zu voxels cut from objects on structure; %zu standing units kept apart; %zu objects "
              "larger than furniture fell back to their parts\n",
              objects, groups.object_of.size(), groups.structure.size(), groups.giant_labels,
              groups.cut.size(), groups.standing_cuts, groups.giant_fallbacks);
  if (params.gsm.objects) {
    const gsm::ExtractionCounts& c = map->extractionCounts();
    std::printf("extractions: %zu objects for the first time, %zu again; %zu updated but "
                "unchanged (kept), %zu held back as flicker, %zu withdrawn\n",
                c.first, c.again, c.unchanged, c.unconfirmed, c.withdrawn);
  }
  return rejected == 0 ? 0 : 1;
}

}  // namespace objdb
