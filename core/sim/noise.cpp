#include "core/sim/noise.h"

#include <cmath>

namespace objdb::sim {
namespace {
constexpr double kPi = 3.14159265358979323846;

uint64_t splitmix64(uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

enum Draw : uint64_t { kGrazing = 0, kEdge = 1, kGaussA = 2 };
}  // namespace

namespace {
// Key of one frame's noise: every draw of the frame hashes (key, pixel, draw) once.
uint64_t frameKey(uint64_t seed, uint64_t frame) { return splitmix64(splitmix64(seed) ^ frame); }

double uniformFromKey(uint64_t key, uint64_t pixel, uint64_t draw) {
  const uint64_t h = splitmix64(key ^ (pixel * 4 + draw));
  return (double(h >> 11) + 0.5) * (1.0 / 9007199254740992.0);  // (0, 1)
}

double normalFromKey(uint64_t key, uint64_t pixel, uint64_t draw) {
  // Box–Muller on the two 32-bit halves of one hash.
  const uint64_t h = splitmix64(key ^ (pixel * 4 + draw));
  // Float math: the noise needs ~7 significant digits, and logf/cosf are several times faster.
  const float u1 = (float(h >> 40) + 0.5f) * (1.0f / 16777216.0f);
  const float u2 = (float((h >> 8) & 0xffffffULL) + 0.5f) * (1.0f / 16777216.0f);
  return std::sqrt(-2.0f * std::log(u1)) * std::cos(2.0f * float(kPi) * u2);
}
}  // namespace

double uniform01(uint64_t seed, uint64_t frame, uint64_t pixel, uint64_t draw) {
  return uniformFromKey(frameKey(seed, frame), pixel, draw);
}

double standardNormal(uint64_t seed, uint64_t frame, uint64_t pixel, uint64_t draw) {
  return normalFromKey(frameKey(seed, frame), pixel, draw);
}

Status DepthNoiseParams::validate() const {
  auto bad = [](const char* field, double v) {
    return absl::InvalidArgumentError(absl::StrFormat("noise.%s is invalid (%g)", field, v));
  };
  if (!(std::isfinite(sigma_base_m) && sigma_base_m >= 0)) return bad("sigma_base_m", sigma_base_m);
  if (!(std::isfinite(sigma_quadratic) && sigma_quadratic >= 0)) return bad("sigma_quadratic", sigma_quadratic);
  if (!std::isfinite(sigma_reference_m)) return bad("sigma_reference_m", sigma_reference_m);
  if (!(std::isfinite(quantum_m) && quantum_m >= 0 && quantum_m < 1)) return bad("quantum_m", quantum_m);
  if (!(std::isfinite(disparity_quantum) && disparity_quantum >= 0 && disparity_quantum < 1)) {
    return bad("disparity_quantum", disparity_quantum);
  }
  if (!(std::isfinite(min_depth_m) && min_depth_m >= 0)) return bad("min_depth_m", min_depth_m);
  if (!(std::isfinite(max_depth_m) && max_depth_m > min_depth_m)) return bad("max_depth_m", max_depth_m);
  if (!(grazing_start_deg >= 0 && grazing_start_deg < grazing_full_deg && grazing_full_deg <= 90)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "noise: need 0 <= grazing_start_deg (%g) < grazing_full_deg (%g) <= 90",
        grazing_start_deg, grazing_full_deg));
  }
  if (!(std::isfinite(edge_jump_m) && edge_jump_m > 0)) return bad("edge_jump_m", edge_jump_m);
  if (!(edge_dropout_probability >= 0 && edge_dropout_probability <= 1)) {
    return bad("edge_dropout_probability", edge_dropout_probability);
  }
  return absl::OkStatus();
}

NoiseStats applyDepthNoise(const DepthNoiseParams& params, uint64_t frame_index,
                           const Image<float>& cos_incidence, DepthImage* depth) {
  NoiseStats stats;
  if (!params.enabled) return stats;
  const int w = depth->width, h = depth->height;
  const DepthImage clean = *depth;  // edges are judged on the noise-free image
  const uint64_t key = frameKey(params.seed, frame_index);
  const float cos_start = std::cos(params.grazing_start_deg * float(kPi) / 180.0f);
  const float cos_full = std::cos(params.grazing_full_deg * float(kPi) / 180.0f);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const size_t idx = size_t(v) * size_t(w) + size_t(u);
      const float z = clean.data[idx];
      float& out = depth->data[idx];
      if (!isValidDepth(z)) {
        out = 0.0f;
        continue;
      }
      if (!(z >= params.min_depth_m && z <= params.max_depth_m)) {
        out = 0.0f;
        ++stats.out_of_range;
        continue;
      }
      const float c = cos_incidence.data[idx];
      if (c < cos_start) {
        const float p = c <= cos_full ? 1.0f : (cos_start - c) / (cos_start - cos_full);
        if (uniformFromKey(key, idx, kGrazing) < p) {
          out = 0.0f;
          ++stats.grazing_dropouts;
          continue;
        }
      }
      bool edge = false;
      const int du[4] = {-1, 1, 0, 0}, dv[4] = {0, 0, -1, 1};
      for (int k = 0; k < 4 && !edge; ++k) {
        const int uu = u + du[k], vv = v + dv[k];
        if (uu < 0 || vv < 0 || uu >= w || vv >= h) continue;
        const float zn = clean.data[size_t(vv) * size_t(w) + size_t(uu)];
        edge = !isValidDepth(zn) || std::abs(zn - z) > params.edge_jump_m;
      }
      if (edge && uniformFromKey(key, idx, kEdge) < params.edge_dropout_probability) {
        out = 0.0f;
        ++stats.edge_dropouts;
        continue;
      }
      float noisy = z + params.sigmaAt(z) * float(normalFromKey(key, idx, kGaussA));
      if (params.disparity_quantum > 0 && noisy > 0.0f) {
        // Quantise 1/z (disparity), not z: the depth step grows as disparity_quantum · z².
        const float steps = std::round(1.0f / (noisy * params.disparity_quantum));
        noisy = steps > 0.0f ? 1.0f / (steps * params.disparity_quantum) : 0.0f;
      }
      if (params.quantum_m > 0) noisy = std::round(noisy / params.quantum_m) * params.quantum_m;
      out = noisy > 0.0f ? noisy : 0.0f;
    }
  }
  return stats;
}

}  // namespace objdb::sim
