// Depth-sensor noise for the synthetic world (Kinect/Tango-like, after Nguyen et al. 2012):
// axial Gaussian noise σ(z) = σ₀ + σ₂·(z − z₀)², quantisation (optionally in disparity, so the
// step grows with z² as in a structured-light sensor), a working range, dropouts at grazing
// angles and at depth edges. Deterministic: every random draw is a hash of (seed, frame
// index, pixel, draw), so the same seed gives the same image whatever the thread count.
#pragma once

#include <cstdint>

#include "core/common/image.h"

namespace objdb::sim {

struct DepthNoiseParams {
  bool enabled = true;
  uint64_t seed = 1;
  float sigma_base_m = 0.0012f;        // σ₀
  float sigma_quadratic = 0.0019f;     // σ₂, metres per metre²
  float sigma_reference_m = 0.4f;      // z₀
  float quantum_m = 0.001f;            // depth step after noise (0 = none)
  // Inverse-depth step in 1/m (0 = off): a structured-light sensor measures disparity ∝ 1/z in
  // fixed sub-pixel steps, so its depth step is ≈ disparity_quantum · z² (Kinect: ≈ 0.0028,
  // Khoshelham & Oude Elberink 2012). Applied after the noise, before quantum_m.
  float disparity_quantum = 0.0f;
  float min_depth_m = 0.2f;            // closer → no measurement
  float max_depth_m = 6.0f;            // farther → no measurement
  float grazing_start_deg = 70.0f;     // dropout probability rises from 0 here ...
  float grazing_full_deg = 85.0f;      // ... to 1 here (angle between ray and normal)
  float edge_jump_m = 0.05f;           // a 4-neighbour this much farther/closer marks an edge
  float edge_dropout_probability = 0.5f;
  Status validate() const;
  float sigmaAt(float z) const {
    const float d = z - sigma_reference_m;
    return sigma_base_m + sigma_quadratic * d * d;
  }
  // Depth step of the disparity quantisation at depth z (0 when it is off).
  float disparityStepAt(float z) const { return disparity_quantum * z * z; }
};

// Counts of what the noise model did to one image.
struct NoiseStats {
  size_t out_of_range = 0;
  size_t grazing_dropouts = 0;
  size_t edge_dropouts = 0;
};

// Applies noise in place to `depth` (metres, 0 = none). `cos_incidence` comes from the renderer
// (same size). Does nothing when !params.enabled.
NoiseStats applyDepthNoise(const DepthNoiseParams& params, uint64_t frame_index,
                           const Image<float>& cos_incidence, DepthImage* depth);

// Deterministic counter-based random numbers (splitmix64 of the key).
double uniform01(uint64_t seed, uint64_t frame, uint64_t pixel, uint64_t draw);
double standardNormal(uint64_t seed, uint64_t frame, uint64_t pixel, uint64_t draw);

}  // namespace objdb::sim
