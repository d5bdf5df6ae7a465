// `objdb report merges`: a picture sheet of the database's merges, for data without ground truth.
// Every model built from two or more segments gets one row: its evidence (surface
// kind, extent, each merge's e_ICP, e_TSDF, o_TSDF and scene checks), its surface cloud, and each
// of its placements drawn over the camera image of the frame that sees it best (most model points
// projecting onto pixels whose measured depth agrees), the rest of the image dimmed. This is how a
// person judges whether a database built from real data merged the right things. Reads the
// database file read-only (also while objdb-server writes it) and the sessions' datasets (any
// layout openDataset reads: objdb, TUM, 7-Scenes).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <cstdint>
#include <map>
#include <set>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "absl/strings/str_format.h"
#include "client/cli_util.h"
#include "client/db_scan.h"
#include "client/db_score.h"
#include "client/merge_sheet.h"
#include "client/commands.h"
#include "core/io/dataset.h"
#include "storage/open_store.h"

namespace objdb {
namespace {

constexpr const char* kCommand = "report";
constexpr const char* kUsage = R"(usage: objdb report merges --db FILE --out SHEET.png DATASET... [options]
       objdb report truth  --db FILE DATASET... [--every N]

Draws every model built from two or more segments as one row of a PNG sheet: its evidence
(surface kind, extent, each merge's e_ICP, e_TSDF, o_TSDF and scene checks), its surface cloud,
and each placement over the camera image of the frame that sees it best (most model points
landing on pixels whose depth agrees within max(3 cm, 2 % of the depth)); the rest of the image is
dimmed. Each DATASET is one session's folder (objdb, TUM or 7-Scenes layout), named after the
folder as `objdb stream` names sessions, or NAME=FOLDER. Placements in sessions without a dataset
are listed but not drawn. The database is opened read-only.

`truth` scores the database against the datasets' ground truth (instances/ and objects.json, in
the objdb layout or a TUM sequence with them): each placement takes the instance most of its
depth-agreeing points fall on over all frames (none below 50 %), and the report prints the
paper's table (placements, mergeable, models, models from >= 2 segments, erroneous merges:
kinds differ, structure merges: floor or wall in a model of >= 2, the share of repeated kinds'
mergeable segments that share a model with their kind at another place: two placements of one
session within 5 cm are one object under two GSM labels) and, per kind, the models it ends in
and the models per true object.

  --db FILE|URI     the database (objdb-server's --db, or a backup of it): an SQLite file or a
                    postgresql:// URI
  --out FILE.png    the sheet
  --max-rows N      at most N models, the ones with the most placements first (default 40)
  --every N         look for the best view in every N-th frame (default 1)
  --min-segments N  merges: draw the models built from at least N segments (default 2; 1 draws
                    every model, the unmerged ones too)
  -h, --help        show this text

exit status: 0 sheet written; 1 the database, a dataset or the sheet failed; 2 command-line error.
)";

struct Options {
  std::string db_path, out;
  size_t max_rows = 40, every = 1, min_segments = 2;
  std::map<std::string, std::string> datasets;  // session → folder
};

// Parses the options both reports take; returns -1 to go on, else the exit status.
int parseOptions(int argc, char** argv, Options* o) {
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> const char* { return i + 1 < argc ? argv[++i] : nullptr; };
    if (a == "-h" || a == "--help") {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (a == "--db" || a == "--out" || a == "--max-rows" || a == "--every" ||
               a == "--min-segments") {
      const char* v = value();
      if (v == nullptr) return cli::usageError(kCommand, a + " needs a value", kUsage);
      if (a == "--db") o->db_path = v;
      if (a == "--out") o->out = v;
      if (a == "--max-rows" || a == "--every" || a == "--min-segments") {
        const long n = std::strtol(v, nullptr, 10);
        if (n < 1) return cli::usageError(kCommand, a + " must be a whole number >= 1", kUsage);
        (a == "--every" ? o->every : a == "--max-rows" ? o->max_rows : o->min_segments) = size_t(n);
      }
    } else if (!a.empty() && a[0] == '-') {
      return cli::usageError(kCommand, "unknown option " + a, kUsage);
    } else {
      const size_t eq = a.find('=');
      const std::string folder = eq == std::string::npos ? a : a.substr(eq + 1);
      std::string name = eq == std::string::npos
                             ? std::filesystem::path(folder).lexically_normal().filename().string()
                             : a.substr(0, eq);
      if (name.empty()) name = std::filesystem::path(folder).parent_path().filename().string();
      o->datasets[name] = folder;
    }
  }
  return -1;
}

// The database, read-only for an SQLite file (nothing is written to a PostgreSQL one either).
StatusOr<std::unique_ptr<storage::Store>> openReadOnly(const std::string& db) {
  storage::StoreOptions options;
  options.sqlite.read_only = true;
  options.sqlite.create_if_missing = false;
  options.postgres.pool_size = 1;
  return storage::openStore(db, options);
}

int merges(int argc, char** argv) {
  Options o;
  if (const int parsed = parseOptions(argc, argv, &o); parsed >= 0) return parsed;
  if (o.db_path.empty() || o.out.empty()) {
    return cli::usageError(kCommand, "--db and --out are required", kUsage);
  }
  const std::string& db_path = o.db_path;
  const std::string& out = o.out;
  auto store = openReadOnly(db_path);
  if (!store.ok()) return cli::reportError(kCommand, store.status());
  auto loaded = cli::loadRows(**store, o.min_segments, o.max_rows);
  if (!loaded.ok()) return cli::reportError(kCommand, loaded.status());
  std::vector<cli::Row> rows = *std::move(loaded);
  std::map<std::string, std::unique_ptr<io::Dataset>> opened;
  if (Status scanned = cli::scanFrames(o.datasets, o.every, &rows, &opened); !scanned.ok()) {
    return cli::reportError(kCommand, scanned);
  }

  const int width = cli::kSheetWidth;
  cv::Mat sheet(40 + cli::kSheetRowHeight * int(std::max<size_t>(rows.size(), 1)), width,
                CV_8UC3, cv::Scalar(30, 30, 30));
  cli::sheetText(&sheet,
       absl::StrFormat("%s: %d models built from %d or more segments (placements over the frame "
                       "that sees them best)",
                       db_path, rows.size(), o.min_segments),
       10, 26, 0.6);
  if (rows.empty()) cli::sheetText(&sheet, "no merges", 10, 70, 0.6);
  for (size_t r = 0; r < rows.size(); ++r) {
    cv::Mat row = sheet(cv::Rect(0, 40 + cli::kSheetRowHeight * int(r), width,
                                 cli::kSheetRowHeight));
    if (Status drawn = cli::drawSheetRow(rows[r], opened, &row); !drawn.ok()) {
      return cli::reportError(kCommand, drawn);
    }
  }
  if (!cv::imwrite(out, sheet)) {
    return cli::reportError(kCommand,
                            absl::UnavailableError(absl::StrFormat("could not write %s", out)));
  }
  std::printf("%zu models drawn to %s (%dx%d)\n", rows.size(), out.c_str(), sheet.cols,
              sheet.rows);
  return 0;
}


int truth(int argc, char** argv) {
  Options o;
  if (const int parsed = parseOptions(argc, argv, &o); parsed >= 0) return parsed;
  if (o.db_path.empty()) return cli::usageError(kCommand, "--db is required", kUsage);
  auto truth = cli::readGroundTruth(o.datasets);
  if (!truth.ok()) return cli::reportError(kCommand, truth.status());
  auto store = openReadOnly(o.db_path);
  if (!store.ok()) return cli::reportError(kCommand, store.status());
  auto loaded = cli::loadRows(**store, 1, SIZE_MAX);
  if (!loaded.ok()) return cli::reportError(kCommand, loaded.status());
  std::vector<cli::Row> rows = *std::move(loaded);
  if (Status scanned = cli::scanFrames(o.datasets, o.every, &rows, nullptr); !scanned.ok()) {
    return cli::reportError(kCommand, scanned);
  }
  cli::printTruthScore(cli::scoreTruth(rows, *truth));
  return 0;
}

}  // namespace

int runReportCommand(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "-h" || std::string(argv[1]) == "--help") {
    std::fputs(kUsage, argc < 2 ? stderr : stdout);
    return argc < 2 ? 2 : 0;
  }
  if (std::string(argv[1]) == "merges") return merges(argc - 1, argv + 1);
  if (std::string(argv[1]) == "truth") return truth(argc - 1, argv + 1);
  return cli::usageError(kCommand, std::string("unknown report \"") + argv[1] + "\"", kUsage);
}

}  // namespace objdb
