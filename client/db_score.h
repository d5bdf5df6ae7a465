// Scores of a database built from datasets, shared by `objdb report truth` and `objdb eval`:
// against ground truth (instances/ + objects.json: the paper's table and models per true object
// by kind), and, for data without it, structure merges: placements lying on the scene's dominant
// planes inside models built from two or more segments.
#pragma once

#include <cstddef>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "client/db_scan.h"
#include "core/common/status.h"
#include "core/io/ground_truth.h"
#include "storage/store.h"

namespace objdb::cli {

// Ground-truth objects by session, then instance id (one id space per session).
using GroundTruth = std::map<std::string, std::map<int, io::GroundTruthObject>>;

// The objects.json of every dataset; FAILED_PRECONDITION naming the folder when one has no
// instances (instances/, or a TUM sequence's labels/), objects.json's own errors when it is
// malformed. Without an objects.json every id seen in the frames is one object of kind
// "label <id>" (class labels, as label-fusion's labels/ hold them); those of `structure_ids`
// (e.g. NYU40's wall 1, floor 2, ceiling 22) are structure.
StatusOr<GroundTruth> readGroundTruth(const std::map<std::string, std::string>& datasets,
                                      const std::set<int>& structure_ids = {});

struct TruthScore {
  size_t placements = 0;          // raw segments in the database
  size_t known = 0;               // with >= 50 % of their points on one instance
  size_t planar = 0, structure = 0;  // the database's flags
  size_t on_structure = 0, on_structure_flagged = 0;  // on true floor/walls; of them flagged
  size_t mergeable = 0;           // neither planar nor structure
  size_t models = 0;              // active models
  size_t multi = 0;               // models from >= 2 segments
  size_t multi_place = 0;         // of them with >= 2 places (not all one surface, cli::places)
  size_t erroneous = 0;           // multi-segment models whose kinds differ
  size_t structure_merges = 0;    // multi-segment models holding true structure
  // Mergeable segments of kinds with two or more of them, and those sharing their model with
  // another of their kind at another place (the paper's recall).
  size_t repeated = 0, with_kind = 0;
  std::vector<std::string> findings;  // one line per erroneous or structure merge
  // Purity and junk, over the placements and models not flagged structure whose points fall on
  // a true object (not structure) most:
  //  - a placement's purity: the share of its depth-agreeing points on that instance;
  //  - a model's purity: over its placements pooled, the share on instances of its kind;
  //  - structure leakage: the share of their points on true structure (floor, walls);
  //  - a model's excess extent: its largest principal span less that of its points whose own
  //    majority instance is of its kind (floor flakes and a neighbour's pieces spread it).
  size_t pure_placements = 0, impure_placements = 0;  // with purity measured; of them < 80 %
  double placement_purity = 0.0;                      // mean
  size_t pure_models = 0, impure_models = 0;          // with purity measured; of them < 95 %
  double model_purity = 0.0, model_purity_min = 0.0;  // mean and least
  double leakage = 0.0;
  size_t extent_models = 0, extent_over = 0;  // models measured; of them with excess > 5 cm
  double extent_excess = 0.0, extent_excess_max = 0.0;  // metres, mean and most
  std::vector<std::string> junk;    // the models with the most excess extent, worst first
  std::vector<std::string> impure;  // the least pure models (under 95 %) and what else they hold
  struct Kind {
    std::string kind;
    size_t objects = 0, segments = 0;
    double models_per_object = 0.0;
    size_t models = 0;  // distinct models holding the kind's mergeable segments, all sessions

  };
  std::vector<Kind> kinds;  // by name
};

// `rows`: every model (loadRows with min_placements 1) scanned over the sessions' frames.
TruthScore scoreTruth(const std::vector<Row>& rows, const GroundTruth& truth);
void printTruthScore(const TruthScore& score);

// What the database holds without any ground truth: its placements by the size of their model
// (full spans along the principal axes of its points, largest first), giant objects (not
// structure, larger than any furniture: more than 2.5 m; a whole room stored as an object),
// the structure share, and objects found at two or more places.
struct CensusScore {
  static constexpr float kSmall = 0.3f;      // m: a mug, a helmet, a box on a shelf
  static constexpr float kFurniture = 1.3f;  // m: a chair is under 1.3 m
  static constexpr float kGiant = 2.5f;      // m: no furniture is larger
  size_t placements = 0;
  size_t structure = 0, planar = 0;          // placements flagged so by the database
  size_t small = 0, furniture = 0, large = 0, giant = 0;  // the other placements by size
  // Of them chair-sized, as the plane-removal + DBSCAN peer counts its clusters: largest span
  // 0.6–1.3 m, smallest at least 0.3 m (peers/plane_dbscan.py, on principal spans here).
  size_t chair_sized = 0;
  double structure_point_share = 0.0;  // share of all placements' model points on structure
  size_t models_at_two_places = 0;     // objects (not structure) at >= 2 places
  float largest_object_m = 0.0f;       // the largest placement not flagged structure
  std::vector<std::string> findings;   // one line per giant object
};
CensusScore scoreCensus(const std::vector<Row>& rows);
void printCensusScore(const CensusScore& score);

struct StructureScore {
  size_t sessions_with_scene = 0;
  size_t planes = 0;              // dominant planes found over all sessions' scenes
  size_t placements = 0;
  size_t planar = 0, structure = 0;  // placements the database flagged planar / structure
  size_t on_planes = 0, on_planes_flagged = 0;  // placements on dominant planes; flagged structure
  size_t multi = 0;               // models from >= 2 segments
  size_t multi_place = 0;         // of them with >= 2 places (cli::places)
  // Models with >= 2 places holding a placement on a dominant plane: structure matched like an
  // object. (One surface under two labels at one place is not a merge of two things.)
  size_t structure_merges = 0;
  std::vector<std::string> findings;  // one line per structure merge
};

// Dominant planes of a session's scene: of the 8 largest planes of its surface voxels (|distance|
// <= half a voxel, observed; fitted within two voxels), those holding at least 2 % of them, and
// of each its connected faces covering at least 1 m² (bigger than an object's face; table tops
// at one height are one plane but separate faces). A placement lies on them when at least half
// of its model points fall within one voxel of their surface voxels.
// Sessions without a stored scene are skipped (counted in sessions_with_scene).
StatusOr<StructureScore> scoreStructure(const storage::Store& store,
                                        const std::vector<Row>& rows);
void printStructureScore(const StructureScore& score);

}  // namespace objdb::cli
