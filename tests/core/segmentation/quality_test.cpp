// Segmentation quality numbers (coverage, under-segmentation, segments per object) on hand-made
// label / instance images whose answers are worked out in the comments.
#include "core/segmentation/quality.h"

#include <gtest/gtest.h>

namespace objdb::segmentation {
namespace {

// 10 × 12 image. Instance 1: columns 0–4 of rows 0–9 (50 px); instance 2: columns 5–9 of rows
// 0–9 (50 px); rows 10–11: no instance. Segment 1: columns 0–3 (40 px, all instance 1);
// segment 2: columns 4–9 (60 px: 10 of instance 1, 50 of instance 2); segment 3: rows 10–11
// (20 px, no instance).
struct HandMade {
  LabelImage labels{10, 12, 0};
  InstanceImage instances{10, 12, 0};
  HandMade() {
    for (int v = 0; v < 12; ++v) {
      for (int u = 0; u < 10; ++u) {
        if (v < 10) {
          instances.at(u, v) = u < 5 ? 1 : 2;
          labels.at(u, v) = u < 4 ? 1 : 2;
        } else {
          labels.at(u, v) = 3;
        }
      }
    }
  }
};

TEST(EvaluateSegmentation, HandMadeTwoInstanceExampleHasKnownNumbers) {
  const HandMade m;
  QualityOptions options;
  options.min_object_pixels = 1;
  const QualityCounts q = evaluateSegmentation(m.labels, m.instances, options);
  EXPECT_EQ(q.segments, 3u);
  // Segment 2 holds 10/60 = 17 % of instance 1 and 83 % of instance 2: both above 10 %.
  EXPECT_EQ(q.under_segmented, 1u);
  EXPECT_DOUBLE_EQ(q.underSegmentationRate(), 1.0 / 3.0);
  EXPECT_EQ(q.objects, 2u);
  EXPECT_DOUBLE_EQ(q.object_pixels, 100.0);
  // Best IoU: instance 1 ↔ segment 1 = 40 / (40 + 50 − 40) = 0.8;
  //           instance 2 ↔ segment 2 = 50 / (60 + 50 − 50) = 5/6.
  EXPECT_NEAR(q.weighted_iou, 50 * 0.8 + 50 * 5.0 / 6.0, 1e-9);
  EXPECT_NEAR(q.coverage(), (0.8 + 5.0 / 6.0) / 2.0, 1e-9);
  // Majority segments: segment 1 of instance 1, segment 2 of instance 2 (50 of 60): the unions
  // are the best segments here.
  EXPECT_NEAR(q.unionCoverage(), q.coverage(), 1e-9);
  // Segments 1 and 2 have an object majority (instances 1 and 2); segment 3 has none.
  EXPECT_EQ(q.object_segments, 2u);
  EXPECT_DOUBLE_EQ(q.segmentsPerObject(), 1.0);
}

// An object cut into parts: on a 10 × 10 image, instance 1 = columns 0–5 (60 px), cut into three
// segments of two columns each; instance 2 = columns 6–9 (40 px), one segment.
TEST(EvaluateSegmentation, UnionCoverageJoinsTheSegmentsMostlyInsideAnObject) {
  LabelImage labels{10, 10, 0};
  InstanceImage instances{10, 10, 0};
  for (int v = 0; v < 10; ++v) {
    for (int u = 0; u < 10; ++u) {
      instances.at(u, v) = u < 6 ? 1 : 2;
      labels.at(u, v) = u < 6 ? 1 + u / 2 : 4;  // segments 1–3 on instance 1, 4 on instance 2
    }
  }
  // Segment 3 also takes column 6 of rows 0–4: 25 px, 20 on instance 1 (majority) and 5 on 2.
  for (int v = 0; v < 5; ++v) labels.at(6, v) = 3;
  QualityOptions options;
  options.min_object_pixels = 1;
  std::map<uint16_t, ObjectScore> scores;
  const QualityCounts q = evaluateSegmentation(labels, instances, options, &scores);
  // Instance 1: best single segment IoU = 20 / (20 + 60 − 20) = 1/3 (segments 1 and 2);
  // union of segments 1–3 = 65 px, 60 on instance 1: IoU = 60 / (65 + 60 − 60) = 12/13.
  EXPECT_NEAR(scores[1].best_iou, 1.0 / 3.0, 1e-9);
  EXPECT_NEAR(scores[1].union_iou, 12.0 / 13.0, 1e-9);
  // Instance 2 (40 px): segment 4 = 35 px all on it: IoU 35 / 40 both ways.
  EXPECT_NEAR(scores[2].best_iou, 35.0 / 40.0, 1e-9);
  EXPECT_NEAR(scores[2].union_iou, 35.0 / 40.0, 1e-9);
  // The best segments: 1 or 2 (a tie) for instance 1, 4 for instance 2.
  EXPECT_TRUE(scores[1].best_label == 1 || scores[1].best_label == 2) << scores[1].best_label;
  EXPECT_EQ(scores[2].best_label, 4);
  EXPECT_NEAR(q.unionCoverage(), (60 * 12.0 / 13.0 + 40 * 35.0 / 40.0) / 100.0, 1e-9);
  EXPECT_GT(q.unionCoverage(), q.coverage());
}

TEST(EvaluateSegmentation, StructureIsScoredForUnderSegmentationOnly) {
  const HandMade m;
  QualityOptions options;
  options.min_object_pixels = 1;
  options.structure_ids = {2};
  const QualityCounts q = evaluateSegmentation(m.labels, m.instances, options);
  EXPECT_EQ(q.objects, 1u);
  EXPECT_NEAR(q.coverage(), 0.8, 1e-9);
  EXPECT_EQ(q.under_segmented, 1u);
  EXPECT_EQ(q.object_segments, 1u);  // segment 2's majority is structure
}

TEST(EvaluateSegmentation, UnderShareAndMinimumObjectSizeApply) {
  const HandMade m;
  QualityOptions options;
  options.min_object_pixels = 1;
  options.under_share = 0.2;  // 10/60 of instance 1 in segment 2 no longer counts
  QualityCounts q = evaluateSegmentation(m.labels, m.instances, options);
  EXPECT_EQ(q.under_segmented, 0u);

  options.under_share = 0.1;
  options.min_object_pixels = 51;  // both 50-pixel instances are too small to score
  q = evaluateSegmentation(m.labels, m.instances, options);
  EXPECT_EQ(q.objects, 0u);
  EXPECT_EQ(q.coverage(), 0.0);
  EXPECT_EQ(q.object_segments, 0u);
  EXPECT_EQ(q.segments, 3u);
}

TEST(EvaluateSegmentation, PerfectSegmentationScoresOneAndCountsAdd) {
  const HandMade m;
  LabelImage perfect = m.labels;
  for (size_t i = 0; i < perfect.data.size(); ++i) perfect.data[i] = m.instances.data[i];
  QualityOptions options;
  options.min_object_pixels = 1;
  const QualityCounts q = evaluateSegmentation(perfect, m.instances, options);
  EXPECT_DOUBLE_EQ(q.coverage(), 1.0);
  EXPECT_EQ(q.under_segmented, 0u);
  EXPECT_EQ(q.segments, 2u);

  QualityCounts total = evaluateSegmentation(m.labels, m.instances, options);
  total.add(q);
  EXPECT_EQ(total.objects, 4u);
  EXPECT_EQ(total.segments, 5u);
  EXPECT_NEAR(total.coverage(), (50 * 0.8 + 50 * 5.0 / 6.0 + 100.0) / 200.0, 1e-9);
  EXPECT_DOUBLE_EQ(total.underSegmentationRate(), 1.0 / 5.0);
  EXPECT_DOUBLE_EQ(QualityCounts{}.coverage(), 0.0);
}

}  // namespace
}  // namespace objdb::segmentation
