// One vector per model for the first stage of retrieval (issue 48): VLAD (Jégou et al. 2010) over
// the model's FPFH descriptors, so that a database of 100,000 models is searched by one dot
// product per model instead of a vote over every stored keypoint descriptor.
//
// Each FPFH is first mapped to its Hellinger form (square roots of the histogram normalised to
// sum 1: unit length, so Euclidean distance compares the distributions the way χ² would); each
// mapped descriptor adds its residual to its nearest codebook word; every word's sum is then
// signed-square-rooted (a burst of near-identical keypoints on a flat face counts less) and
// normalised to unit length (intra-normalisation: a word with many keypoints does not drown the
// rest), and the whole vector is normalised. Two models compare by the dot product of their
// vectors (cosine similarity, 1 for identical descriptor sets).
//
// The codebook is fixed (fpfh_codebook.inc, trained by bench/codebook_train on the kitchen
// preset's models, none of the evaluation datasets): the same FPFH parameters give the same
// words everywhere, so descriptors stored by one server compare with another's.
// kCodebookVersion names it: stored global descriptors of another version are recomputed.
#pragma once

#include <cstdint>
#include <vector>

#include "core/model/object_model.h"

namespace objdb::model {

// Words × FPFH bins, row-major, in the Hellinger space.
struct Codebook {
  int words = 0;
  std::vector<Fpfh> centres;
};

// The codebook every model's global descriptor uses, and its version.
const Codebook& fpfhCodebook();
inline constexpr int kCodebookVersion = 1;
// Length of a global descriptor with the fixed codebook (words × 33).
int globalDescriptorSize();

// Squared Euclidean distance of two FPFH (the kd-trees' metric, and the codebook's).
float fpfhSquaredDistance(const Fpfh& a, const Fpfh& b);

// The Hellinger form of an FPFH: sqrt(d / Σd) per bin (Σ of squares 1); all zero when Σd ≤ 0.
Fpfh hellinger(const Fpfh& descriptor);

// The VLAD vector of `descriptors` (FPFH as computeFpfh gives them) on `codebook`: unit length,
// or all zero (not empty) for no descriptors.
std::vector<float> globalDescriptor(const std::vector<Fpfh>& descriptors,
                                    const Codebook& codebook = fpfhCodebook());

// Cosine similarity of two global descriptors of one length (their dot product): 1 identical,
// 0 nothing in common; 0 when either is all zero or the lengths differ.
float globalSimilarity(const std::vector<float>& a, const std::vector<float>& b);

}  // namespace objdb::model
