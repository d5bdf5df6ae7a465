// `objdb fuse`: integrates every frame of a dataset (objdb or TUM layout) into a TSDF volume and
// writes the surface as a PLY mesh — the geometry half of the GSM on any posed depth sequence.
#include <cstdio>
#include <filesystem>
#include <string>

#include "client/cli_util.h"
#include "client/commands.h"
#include "client/progress.h"
#include "core/io/dataset.h"
#include "core/io/mesh_io.h"
#include "core/tsdf/mesh_extraction.h"
#include "core/tsdf/tsdf_integrator.h"

namespace objdb {
namespace {

constexpr const char* kUsage = R"(usage: objdb fuse --dataset DIR --out MESH.ply [options]

Integrates the frames of a dataset (objdb or TUM layout) into a TSDF volume and writes the
extracted surface (vertex colours when the dataset has colour) as a binary PLY mesh.

  --dataset DIR     dataset folder
  --out FILE        output mesh (.ply)
  --config FILE     parameters as JSON; the "tsdf" section applies (voxel size, truncation, ...)
  --voxel-size M    shortcut for tsdf.voxel_size_m (default 0.02)
  --every N         use every N-th frame (default 1)
  --threads N       integration threads (default 2)
)";

int usageError(const std::string& message) { return cli::usageError("fuse", message, kUsage); }
int reportError(const Status& status) { return cli::reportError("fuse", status); }

}  // namespace

int runFuseCommand(int argc, char** argv) {
  cli::DatasetJobOptions job;
  double voxel = 0.0;
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
    } else if (a == "--voxel-size") {
      char* end = nullptr;
      voxel = std::strtod(value, &end);
      if (end == value || *end != '\0' || !(voxel > 0.0)) return usageError("--voxel-size needs a positive number of metres");
    } else {
      return usageError("unknown option '" + a + "'");
    }
  }
  if (job.dataset.empty() || job.out.empty()) return usageError("--dataset and --out are required");
  auto loaded = cli::loadParams(job.config);
  if (!loaded.ok()) return reportError(loaded.status());
  Params params = *loaded;
  if (voxel > 0.0) {
    params.tsdf.voxel_size_m = float(voxel);
    if (Status s = params.tsdf.validate(); !s.ok()) return reportError(s);
  }
  auto opened = io::openDataset(job.dataset);
  if (!opened.ok()) return reportError(opened.status());
  const io::Dataset& ds = **opened;
  auto integrator = tsdf::TsdfIntegrator::create(params.tsdf, ds.intrinsics(), int(job.threads));
  if (!integrator.ok()) return reportError(integrator.status());
  auto layer = tsdf::TsdfLayer::create(params.tsdf.voxel_size_m, params.tsdf.voxels_per_side);
  if (!layer.ok()) return reportError(layer.status());

  tsdf::IntegrationStats total;
  size_t used = 0, rejected = 0;
  cli::ProgressBar bar("fusing", (ds.size() + size_t(job.every) - 1) / size_t(job.every));
  for (size_t i = 0; i < ds.size(); i += size_t(job.every)) {
    auto frame = ds.loadFrame(i);
    if (!frame.ok()) return reportError(frame.status());
    auto stats = integrator->integrate(frame->depth, frame->T_world_camera, &*layer,
                                       frame->color ? &*frame->color : nullptr);
    if (!stats.ok()) {
      // A bad frame (pose, size) is reported and skipped; the volume is untouched by it.
      std::fprintf(stderr, "\nobjdb fuse: frame %zu skipped: %s\n", i,
                   std::string(stats.status().message()).c_str());
      ++rejected;
    } else {
      ++used;
      total.invalid_depth += stats->invalid_depth;
      total.out_of_range += stats->out_of_range;
      total.milliseconds += stats->milliseconds;
    }
    bar.update(used + rejected);
  }
  bar.finish();
  tsdf::MeshLayer meshes(params.tsdf.mesh_min_weight);
  meshes.update(&*layer, true);
  const TriangleMesh mesh = meshes.mesh();
  if (Status s = io::writePlyMesh(job.out, mesh); !s.ok()) return reportError(s);
  std::printf("%zu frames fused (%zu skipped), %.2f ms/frame integration; %zu blocks, %.1f MB of "
              "voxels; %zu invalid and %zu out-of-range depth pixels skipped\n",
              used, rejected, used ? total.milliseconds / double(used) : 0.0, layer->numBlocks(),
              double(layer->voxelBytes()) / 1e6, total.invalid_depth, total.out_of_range);
  std::printf("mesh: %zu vertices, %zu triangles, %.2f m² -> %s\n", mesh.vertices.size(),
              mesh.triangles.size(), mesh.surfaceArea(), job.out.c_str());
  return rejected == 0 ? 0 : 1;
}

}  // namespace objdb
