// TSDF verification and merging (paper §III-C.4): two grids are compared voxel by voxel after one
// is resampled into the other's lattice by trilinear interpolation; the overlap o_TSDF (voxels
// observed in both) and the RMSE e_TSDF of the distance pairs decide. An upside-down
// registration puts positive distances (free space) on negative ones (inside): its RMSE is large
// even when the surfaces coincide. Written by hand: no library does TSDF-to-TSDF checks.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "core/common/image.h"
#include "core/common/params.h"
#include "core/common/transform.h"
#include "core/tsdf/tsdf_layer.h"

namespace objdb::matching {

struct GridAgreement {
  size_t overlap = 0;   // o_TSDF: fixed voxels whose position is observed in `moving` too
  size_t compared = 0;  // observed voxels of `fixed` looked at
  double rmse = 0.0;    // e_TSDF over the overlap, metres (0 when there is none)
};

// Every observed voxel of `fixed` is looked up in `moving` at T_moving_fixed · centre (trilinear,
// all 8 neighbours observed). T_fixed_moving maps moving's frame into fixed's.
GridAgreement compareGrids(const tsdf::TsdfLayer& fixed, const tsdf::TsdfLayer& moving,
                           const Transform& T_fixed_moving);

// Colour of the surface where both grids saw it (ours; the paper compares geometry only). Two
// objects that agree on shape can differ in colour: a chair's back and a sofa's arm, a fire
// extinguisher and a gas cylinder. Every surface voxel of `fixed` (observed, |d| ≤ one voxel,
// coloured) is paired with the nearest voxel of `moving` at T_moving_fixed · centre when that one
// is a coloured surface voxel too. Colour is compared as chromaticity, rgb / (r + g + b), which a
// change of exposure or of shading leaves alone: the distance of a pair is half the L1 distance
// of its chromaticities (0 = the same hue and saturation, 1 = disjoint channels). A voxel darker
// than kMinColourSum (or never coloured: a session without colour leaves 0, 0, 0) has no
// reliable chromaticity and is not paired.
struct ColourAgreement {
  size_t pairs = 0;                // surface voxels both grids coloured
  double median_distance = 0.0;    // median chromaticity distance over the pairs (0 without)
  double mean_distance = 0.0;
  // The pairs whose two voxels both have a hue (saturation ≥ kMinSaturation): only they can
  // confirm a match. Grey, white and black surfaces agree with any other grey.
  size_t chromatic_pairs = 0;
  double chromatic_median_distance = 0.0;
};
inline constexpr int kMinColourSum = 60;  // r + g + b
// Saturation: the chromaticity distance from grey. A wall or floor in the lounge is ~0.01, a
// grey SUN3D partition 0.02, its brown sofa 0.10, the green chair seats 0.14.
inline constexpr double kMinSaturation = 0.05;
double chromaticityDistance(const Rgb8& a, const Rgb8& b);
ColourAgreement compareColours(const tsdf::TsdfLayer& fixed, const tsdf::TsdfLayer& moving,
                               const Transform& T_fixed_moving);

struct Verdict {
  bool accepted = false;
  GridAgreement agreement;
  double min_overlap = 0.0;  // o*_TSDF at the grid's voxel size
  std::string reason;        // why not, for logs and merge records
};
// Accepts when e_TSDF ≤ e*_TSDF and o_TSDF ≥ o*_TSDF (scaled to voxel_size, see MergingParams).
Verdict judge(const GridAgreement& agreement, const MergingParams& params, double voxel_size_m);

// t̂ = target ⊕ source: `source` resampled into target's lattice (T_target_source maps source into
// target) and fused by weight: d = (w_t d_t + w_s d_s) / (w_t + w_s), w = min(w_t + w_s,
// max_weight). Voxels only the source observed are added. Colours are fused by the same weights
// from the source voxel nearest to each target voxel (a target voxel keeps its own colour where
// the source has none). Grids must share the voxel size.
// kFillUnobserved (scene completion) leaves the target's observed voxels as they are. Returns the
// number of target voxels written; `written_near_surface` gets those within one voxel of the
// surface (|distance| ≤ voxel size).
enum class MergeMode {
  kFuse,            // weighted average where both observed, source values where only it did
  kFillUnobserved,  // only voxels the target did not observe (MergeOptions) are written
};
struct MergeOptions {
  MergeMode mode = MergeMode::kFuse;
  // kFillUnobserved: target voxels at least this heavy count as observed and are kept. Lighter
  // ones (a scene's voxels seen too little to be meshed, below its mesh_min_weight) are fused with
  // the source like unobserved ones. 0: every voxel with weight counts as observed.
  float observed_min_weight = 0.0f;
  // When given, only the target voxels around these source voxels are written (and, for kFuse,
  // the target's observed ones); interpolation still reads the whole source.
  const std::vector<tsdf::VoxelIndex>* source_region = nullptr;
};
size_t mergeGrids(tsdf::TsdfLayer* target, const tsdf::TsdfLayer& source,
                  const Transform& T_target_source, float max_weight,
                  const MergeOptions& options = {}, size_t* written_near_surface = nullptr);

}  // namespace objdb::matching
