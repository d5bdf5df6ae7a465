// Parameter structs of every pipeline stage, with the paper's defaults (table I) and the
// reference implementations' defaults where the paper is silent (voxblox, PCL). One struct per
// configurable thing; each has validate() naming the bad field. `Params` bundles them; config
// files (JSON) map onto it in params_io.h, nowhere else.
#pragma once

#include <string>

#include "core/common/status.h"

namespace objdb {

// §III-A depth segmentation (defaults of ethz-asl depth_segmentation at VGA). Window sizes and
// the minimum segment size are given for 640×480 and scaled to other resolutions.
struct SegmentationParams {
  // 3×3 hole-filling passes (0 = off): pinholes whose neighbours lie on one surface are closed,
  // holes on depth edges stay (fillDepthHoles). 1: a RealSense's registered depth has a grid of
  // pinholes that otherwise splits every surface into pixel-sized regions.
  int fill_holes_iterations = 1;
  int normal_window_px = 13;                  // side of the normal-estimation window
  float normal_max_relative_distance = 0.05f; // neighbours used only if |Δz| < this · z
  int discontinuity_window_px = 3;            // kernel of the depth-discontinuity filter
  float discontinuity_threshold = 0.03f;      // max relative depth jump (|Δd| / d)
  int convexity_window_px = 5;                // min-convexity window
  float convexity_threshold = 0.97f;          // below → concave boundary
  float convexity_offset_m = 0.0005f;         // offsets above −this along the normal are convex
  // Ours: + this · z² per m² (the sensor's noise grows about with depth², so a surface seen from
  // farther needs a larger offset to stay convex; 0..0.01). Twice the default over-merges clean
  // frames.
  float convexity_offset_per_m2 = 0.0002f;
  int min_segment_px = 500;                   // smaller regions are dropped (VGA; scale for others)
  float max_label_growth_distance_m = 0.05f;  // edge pixels join a neighbour label within this
  int label_growth_iterations = 8;            // passes of growing labels into edge pixels
  Status validate() const;
};

// TSDF volume (voxblox++ iodb_node defaults).
struct TsdfParams {
  float voxel_size_m = 0.02f;       // edge of a voxel
  int voxels_per_side = 8;          // block = voxels_per_side³ voxels
  float truncation_voxels = 3.0f;   // truncation distance in voxels
  float max_ray_length_m = 3.5f;    // depth beyond this is skipped (counted); 0.01..100 m
  float min_ray_length_m = 0.1f;    // depth below this is skipped (counted)
  float max_weight = 1000.0f;       // voxel weights saturate here
  float mesh_min_weight = 3.0f;     // voxels lighter than this are not meshed
  // Ours. Free space in front of the band, metres: blocks this far in front of each measured
  // surface are allocated too, so their voxels are observed as empty (+truncation); scene
  // completion then fills nothing there (it must not fill space a camera saw through). 0 = only
  // the band. 0..2 m.
  float carve_distance_m = 0.15f;
  float truncationDistance() const { return truncation_voxels * voxel_size_m; }
  Status validate() const;
};

// §III-B Global Segmentation Map (voxblox++ iodb_node defaults).
struct GsmParams {
  int min_label_voxels = 20;             // labels with fewer voxels are not extracted
  float association_overlap_ratio = 0.2f; // a segment takes a label covering this share of it
  bool label_history = true;             // false: one label + confidence per voxel (ablation)
  float merge_overlap_ratio = 0.1f;      // pairwise label overlap that counts as evidence
  int merge_min_frames = 2;              // frames of evidence before two labels merge
  // Ours: besides merge_min_frames, the frames in which one segment covered both labels must be
  // at least this share of the frames that saw them touching (in the others each was claimed by
  // a segment of its own). 0 = the paper's rule. 0.5: two labels merge only when one segment
  // covered both in most of the frames that saw them touch, so two noisy frames do not glue an
  // object standing on another to it.
  float merge_min_joint_share = 0.5f;
  int extraction_age_frames = 10;        // a label untouched this long is extracted
  // Whole objects (ours; core/gsm/objects.h): above the convex labels, the labels that
  // touch (voxels within object_gap_m) are grouped into objects, except across room structure
  // (labels mostly on the room's bounding faces, core/gsm/room_structure.h) and
  // across a support (a label resting on the face of a planar label that surrounds the contact
  // on all four sides within object_support_probe_m: a mug on a table, a box on a shelf).
  // `objects` true: the GSM extracts whole objects (a segment per group, with its parts);
  // false: every label alone (the paper's segments). Groups are recomputed every
  // object_update_frames frames (and at a flush); extraction runs then.
  bool objects = true;
  float object_gap_m = 0.02f;
  int object_min_contact_voxels = 3;  // voxels of two labels next to the other, to connect
  // Room structure (core/gsm/room_structure.h): planes found in the whole map's surface, each
  // with a distance band measured from its own voxels' spread (so it grows with the depth noise
  // σ(z) at the depth it was seen from, and with pose drift), at least one voxel. A face of a
  // plane bounds the room (a floor, a wall, a ceiling, a cabinet front or a counter top) when it
  // spans at least object_structure_extent_m along its longer in-plane axis and
  // structure_min_span_m along its shorter one (bigger than a face of furniture: a chair's seat
  // or back, a box's side is under 1 m × 0.5 m) and at most structure_max_behind_share of its
  // voxels' count of observed surface lies behind it inside its footprint (nothing was seen
  // behind a wall or a floor; under a table top there are chairs and floor). Voxels on such a
  // face are a barrier: labels mostly on it are structure, other labels' voxels on it are cut
  // from their objects.
  float object_structure_extent_m = 1.0f;
  float structure_min_span_m = 0.5f;
  float structure_max_behind_share = 0.05f;
  // A surface voxel joins a plane direction when its TSDF-gradient normal lies within this
  // angle: TSDF normals of a noisy plane at 2 cm voxels scatter by 10–20°, the distance band
  // then decides.
  float structure_normal_deg = 30.0f;
  // A plane's distance band: this many robust σ (1.4826 · MAD) of its voxels' offsets, at least a
  // voxel (3: a Gaussian's 99.7 %).
  float structure_band_sigmas = 3.0f;
  // An object larger than furniture can be (a dining table is about 2 m, a sofa 2.3 m; a room's
  // wall or floor is more) is never one object: it falls back to its parts (counted,
  // ObjectGroups::giant_fallbacks), and a single part that large is room structure.
  float object_max_extent_m = 2.5f;
  float object_support_probe_m = 0.3f;
  // ... and only when the object resting there spans at most this share of the support's extent
  // along both of its axes (a pedestal carrying a seat as wide as its base is not a mug).
  float object_support_max_ratio = 0.7f;
  // An object also takes the voxels of room structure that stand off the structure's plane, on
  // its observed side, by more than a voxel and more than twice the plane's own spread, up to
  // this height, inside the object's footprint and connected to its voxels: a chair's or a
  // table's base disc a few centimetres high, which the segmenter cannot tell from the floor
  // (core/gsm/objects.h). 0 = off.
  float object_annex_height_m = 0.1f;
  // Two labels also connect across a gap the cameras never saw into, up to this long, straight
  // along the normal of the structure the lower one stands on, when the upper one's object
  // floats (core/gsm/objects.h): a pedestal under a seat or a table top, whose top is in their
  // shadow. Metres; 0 = off. 0.3 m: the column of a table or chair pedestal under its top
  // (furniture heights put it between 0.2 and 0.5 m). Only an object that floats (touches no
  // structure, rests on no support) is joined so: a chair pushed under a desk that stands on its
  // own legs stays apart.
  float object_shadow_gap_m = 0.3f;
  int object_update_frames = 10;
  // The room structure is found again every this many frames (and at a flush); the regroupings
  // in between use the last one. The room changes slowly, and finding it reads the whole map
  // (docs/structure.md, "What it costs").
  int structure_update_frames = 50;
  // An object is extracted only once one of its labels was voted for in at least this many
  // frames (ours): a label seen in one frame alone is flicker at a segment's border (a sliver the
  // association did not tie to its neighbour), which the next frames' votes take back; each
  // would cost a database insert and a withdrawal. At a flush every object is extracted: what
  // still stands then is a surface seen once. 1 = every label.
  int object_min_frames = 2;
  // An object extracted before, of the same parts, is extracted again only when its voxel set
  // changed by at least this share since (the share of the larger of its two voxel sets, then
  // and now, that the other lacks; ours). Each re-extraction is a full database insert (surface, features, matching, checks); a
  // surface seen again from where it was seen before gains or loses a few voxels along its
  // outline and nothing else. The change is measured against the last extraction, so slow
  // growth adds up until it counts. 0 = re-extract on every update (the paper). 0.1: a tenth of
  // an object's voxels is more than the outline a view adds (docs/gsm.md, "Extraction").
  float reextract_min_change = 0.1f;
  Status validate() const;
};

// §III-C.1 object models: surface cloud and planarity test (ours; the paper gives no values).
struct ModelParams {
  // A segment is planar (stored, never matched) when at least planar_inlier_ratio of its surface
  // points lie within the plane distance of one RANSAC plane. The distance follows the sensor's
  // depth noise at the depth the segment was seen from (core/model/structure.h):
  // max(plane_distance_m, plane_noise_sigmas · σ(z)), σ(z) = noise_sigma0_m + noise_sigma2_m ·
  // (z − noise_z0_m)² (Nguyen et al. 2012, Kinect-class axial noise). At 1 m that is the 1 cm
  // floor, at 3 m 4.2 cm: a real wall at 3 m is planar, as it is.
  float plane_distance_m = 0.01f;
  float planar_inlier_ratio = 0.9f;
  int plane_ransac_iterations = 200;
  float plane_noise_sigmas = 3.0f;
  float noise_sigma0_m = 0.0012f;
  float noise_sigma2_m = 0.0019f;
  float noise_z0_m = 0.4f;
  // Room structure (ours): a segment is structure (stored, listed as such, never matched
  // or merged) when one of its first structure_max_planes RANSAC planes (at the same distance)
  // holds at least structure_min_share of its points and spans at least structure_min_extent_m
  // along both of its in-plane axes (5th to 95th percentile of its inliers): a flat face bigger
  // than an object can be (floor, wall, ceiling, partition), alone or with what sticks to it
  // (a shelf on a wall, a kick plate below a cabinet, the other wall of a corner).
  float structure_min_extent_m = 1.0f;
  float structure_min_share = 0.3f;
  int structure_max_planes = 3;
  // Fewer surface points than this: too small to describe, stored but never matched.
  int min_points = 100;
  // The surface cloud is resampled to one point (mean position and normal) per cube of this
  // side: marching tetrahedra gives several vertices per voxel, and keypoint and FPFH costs grow
  // with the number of points inside their radii. Metric, so table I's radii mean the same at
  // every voxel size.
  float cloud_spacing_m = 0.01f;
  // σ(z): the sensor's axial noise at depth_m (0 when the depth is unknown, 0 or not finite).
  float depthNoise(float depth_m) const;
  // The plane distance for a surface seen from depth_m (0 = unknown: plane_distance_m).
  float planeDistance(float depth_m) const;
  Status validate() const;
};

// §III-C.2 keypoints (table I).
struct KeypointParams {
  float harris_radius_m = 0.03f;         // r_H
  int harris_min_neighbors = 10;         // k_NN^min (Harris3D)
  float harris_curvature_threshold = 0.07f;  // t_curv
  float harris_response_threshold = 1e-6f;   // t_resp
  float iss_border_radius_m = 0.02f;     // r_b
  float iss_salient_radius_m = 0.06f;    // r_s
  float iss_non_max_radius_m = 0.08f;    // r_nm
  int iss_min_neighbors = 5;             // k_NN^min (ISS)
  // Ours, not in table I: also one keypoint per cube of this side (the cloud point nearest the
  // cube's centre), so that small or smooth segments get enough correspondences; 0 = off.
  // Metres; 5 cm gives a chair-sized segment hundreds of keypoints at any voxel size.
  float uniform_spacing_m = 0.05f;
  Status validate() const;
};

// §III-C.2 descriptors (table I).
struct DescriptorParams {
  float fpfh_radius_m = 0.10f;  // r
  // Ours: the histograms are built over the model cloud resampled to this spacing (keypoints
  // stay where they are); 0 = over the model cloud itself. Metres. FPFH's cost grows with the
  // square of the points within r; at 2 cm a 10 cm radius still holds some 75 points.
  float surface_spacing_m = 0.02f;
  Status validate() const;
};

// §III-C.3 matching and registration (table I).
struct MatchingParams {
  float similarity_threshold = 0.4f;  // t_sim
  int k_nn = 5;                       // k_NN best descriptor matches per keypoint
  float icp_max_rmse_m = 0.02f;       // e*_ICP
  // Ours (not in table I): RANSAC over the descriptor matches, then point-to-plane ICP.
  float ransac_inlier_distance_m = 0.04f;  // a match agrees with a transform within this
  int ransac_iterations = 10000;
  int ransac_min_inliers = 4;              // fewer: no consistent set, candidate rejected
  // The coarse transform must not be contradicted by the target's TSDF: (agreeing − disagreeing)
  // source surface points / sampled points ≥ this, or the candidate is rejected before ICP.
  float coarse_min_agreement = 0.0f;
  float icp_max_correspondence_m = 0.05f;  // ICP pairs farther apart are ignored
  // ICP starts from the RANSAC transform, already within a few centimetres: 15 iterations settle.
  int icp_iterations = 15;
  // The source cloud is thinned to this for ICP.
  int icp_max_source_points = 400;
  Status validate() const;
};

// §III-C.4 merging and verification (table I).
struct MergingParams {
  float tsdf_max_rmse_m = 0.02f;  // e*_TSDF
  // o*_TSDF: the paper's 10^4 overlapping voxels. Overlap is counted in the truncation band, a
  // shell of (2 · truncation_voxels) voxels around the surface, so for a fixed surface area it
  // grows with 1 / voxel²: the threshold is given at reference_voxel_size_m and scaled by
  // (reference / actual voxel size)² (see minOverlapVoxels).
  float tsdf_min_overlap_voxels = 1e4f;
  float reference_voxel_size_m = 0.01f;
  // Ours (scene completion): a placed model fills only the scene voxels within this many voxels
  // of the model's own surface voxels. Beyond them a model grid holds the truncation band of
  // whatever surrounded each observation (floor, walls, neighbours), which is not the object.
  // At most 4: the region has (2 · margin + 1)³ voxels per surface voxel, and a truncation band
  // of 3 voxels is covered at 3.
  int completion_margin_voxels = 1;
  // Ours: a registration that the grids accept is still rejected when the two models' colours
  // disagree where both saw the surface (matching::compareColours): the median chromaticity
  // distance of at least colour_min_pairs coloured surface-voxel pairs above colour_max_distance.
  // Shape alone cannot tell a chair's back from a sofa's arm, nor a fire extinguisher from a gas
  // cylinder. Models without colour (sessions streamed without it, dark surfaces) are judged on
  // geometry alone. 0 turns the check off. The default lies between the distances of same-kind
  // and of wrong candidates (docs/database.md, "Colour as evidence").
  float colour_max_distance = 0.12f;
  int colour_min_pairs = 30;
  // Ours: a real sweep can be noisier than the paper's thresholds allow (its depth may disagree
  // with its own map by twice the Kinect-class σ(z), poses included). The GSM measures each
  // session's noise as a multiple s of σ(z) (gsm::SurfaceNoise; a synthetic session with the
  // sensor model's noise measures about 1). A new segment seen from depth z in a session with
  // s > 1 may pass the model checks with e*_ICP and e*_TSDF each raised by
  // noise_sigmas · (s − 1) · σ(z) (ModelParams::depthNoise), but only where colour confirms the
  // match: at least colour_min_pairs pairs of chromatic voxels (both farther than
  // matching::kMinSaturation from grey) agree within colour_max_distance. Grey or colourless
  // surfaces, joins of two stored models, and every check against a scene keep the paper's
  // thresholds. 0 turns the loosening off, the default: where the paper's thresholds refuse a
  // pair, the safe answer is no merge (docs/database.md, "Loosening").
  float noise_sigmas = 0.0f;
  double minOverlapVoxels(double voxel_size_m) const;
  Status validate() const;
};

// Object database (Algorithm 1 around the paper's steps; ours).
struct DatabaseParams {
  // Candidate prefilter: every keypoint descriptor of a new model votes for the models owning
  // its prefilter_neighbours nearest descriptors (similarity ≥ t_sim); models with at least
  // prefilter_min_votes votes are candidates, the max_candidates most voted first.
  int prefilter_neighbours = 20;
  int prefilter_min_votes = 3;
  // The nearest descriptors are searched approximately when > 0: FLANN's (1 + ε) bound in each
  // kd-tree (deterministic). An exact search (0) in 33-D FPFH space visits most of the tree: its
  // time grows with the stored descriptors (docs/database.md, "Scale").
  float prefilter_epsilon = 2.0f;
  // Two-stage retrieval (issue 48): the vote above runs only over the descriptors of the
  // `shortlist` models whose global descriptors (model/global_descriptor.h: VLAD over their FPFH)
  // are most similar to the new model's; 0 votes over every stored model's descriptors (the
  // search before the short list, kept for comparison). 4 × max_candidates: the vote still picks
  // the candidates it registers from several times as many models as it registers, and a
  // database of many copies of one object fills the list with copies of it (docs/database.md,
  // "Scale", measures the list's recall of the merges the full vote accepts).
  int shortlist = 64;
  // The candidates registered per insert at most: bounds the insert's time.
  int max_candidates = 16;
  // Candidates are evaluated in waves of `threads`, most voted first; once this many have been
  // accepted no further wave starts (0: evaluate all). Bounds the insert time when many stored
  // models are copies of one object; the waves keep the result independent of thread timing.
  int stop_after_accepted = 4;
  // Models that each accepted the same segment hold one object: the segment merges into the
  // best of them, and each other one is then registered onto the result (ICP from the transform
  // the segment gives, T_best←segment · T_other←segment⁻¹), verified model to model and at every
  // pose of both against its scene, and merged in when it passes (its state becomes merged).
  // Parts of one chair kind that never overlapped each other join through a view covering both.
  bool merge_co_accepted = true;
  int threads = 2;  // candidate registrations in parallel
  Status validate() const;
};

struct Params {
  SegmentationParams segmentation;
  TsdfParams tsdf;
  GsmParams gsm;
  ModelParams model;
  KeypointParams keypoints;
  DescriptorParams descriptors;
  MatchingParams matching;
  MergingParams merging;
  DatabaseParams database;
  Status validate() const;
};

}  // namespace objdb
