// storage_bench: throughput of the object store (SQLite and PostgreSQL) on
// realistic models — a
// chair-sized TSDF at 1 cm (seat, back, four legs; observed band ±3 voxels), its surface cloud,
// ISS ∪ Harris3D keypoints and FPFH descriptors built by core/model exactly as the database does.
// Prints insert and load throughput (models/s, MB/s of blobs), the time to open a database of N
// models (with its quick_check) and to load the index the matcher needs (descriptors of every
// model into the kd-tree), the database's incremental prefilter index (a model put per insert,
// its query against one tree's), and the file size. Not a test: figures vary with the machine.
//
//   build/bin/storage_bench [--models 1000] [--dir /tmp] [--synchronous FULL|NORMAL]
//   build/bin/storage_bench --db postgresql://USER@HOST/EMPTY_DB [--models 1000]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "absl/strings/str_format.h"
#include "bench/chair_model.h"
#include "core/common/logging.h"
#include "core/common/params.h"
#include "core/database/prefilter_index.h"
#include "core/matching/registration.h"
#include "core/model/object_model.h"
#include "storage/blob_codec.h"
#include "storage/open_store.h"

namespace objdb {
namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

// The model the database would build from a chair segment, with 500 described keypoints.
model::ObjectModel chairModel(int variant) {
  auto built = bench::describedChairModel(variant);
  if (!built.ok()) {
    std::fprintf(stderr, "storage_bench: %s\n", std::string(built.status().message()).c_str());
    std::exit(1);
  }
  return std::move(*built);
}

size_t blobBytes(const model::ObjectModel& m) {
  return storage::encodeTsdfGrid(m.grid).size() + storage::encodeVoxelList(m.surface_voxels).size() +
         storage::encodePointCloud(m.cloud).size() + storage::encodeIndices(m.keypoint_indices).size() +
         storage::encodeDescriptors(m.descriptors).size();
}

}  // namespace
}  // namespace objdb

int main(int argc, char** argv) {
  using namespace objdb;
  int models = 1000;
  std::string dir = "/tmp", synchronous = "FULL", db;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string name = argv[i];
    if (name == "--models") {
      models = std::atoi(argv[i + 1]);
    } else if (name == "--dir") {
      dir = argv[i + 1];
    } else if (name == "--synchronous") {
      synchronous = argv[i + 1];
    } else if (name == "--db") {
      db = argv[i + 1];
    } else {
      std::fprintf(stderr, "usage: storage_bench [--models N] [--dir DIR] [--synchronous FULL|NORMAL] "
                   "[--db SQLITE_FILE|POSTGRES_URI]\n");
      return 2;
    }
  }
  if (models < 1 || models > 1000000) {
    std::fprintf(stderr, "storage_bench: --models must be in [1, 1000000]\n");
    return 2;
  }
  setLogLevel("warn");
  std::vector<model::ObjectModel> kinds;
  for (int v = 0; v < 4; ++v) kinds.push_back(chairModel(v));
  const model::ObjectModel& chair = kinds[0];
  size_t raw_voxel_bytes = chair.grid.numBlocks() * 512 * sizeof(tsdf::TsdfVoxel);
  std::printf("model: %zu TSDF blocks at 1 cm (%.2f MB of voxels in memory), %zu cloud points, "
              "%zu keypoints with FPFH; %.1f kB of blobs after compression (grid %.1f kB, cloud "
              "%.1f kB, descriptors %.1f kB)\n",
              chair.grid.numBlocks(), double(raw_voxel_bytes) / 1e6, chair.cloud.points.size(),
              chair.keypoint_indices.size(), double(blobBytes(chair)) / 1e3,
              double(storage::encodeTsdfGrid(chair.grid).size()) / 1e3,
              double(storage::encodePointCloud(chair.cloud).size()) / 1e3,
              double(storage::encodeDescriptors(chair.descriptors).size()) / 1e3);

  // A file of our own (removed first), or the database the caller names, which must be empty.
  const bool own_file = db.empty();
  const std::string path =
      own_file ? (std::filesystem::path(dir) / "objdb_storage_bench.sqlite").string() : db;
  if (own_file) {
    for (const char* suffix : {"", "-wal", "-shm"}) std::filesystem::remove(path + suffix);
  }
  storage::StoreOptions options;
  options.sqlite.synchronous = synchronous;
  auto store = storage::openStore(path, options);
  if (!store.ok()) {
    std::fprintf(stderr, "storage_bench: %s\n", std::string(store.status().message()).c_str());
    return 1;
  }
  if (!(*store)->modelIds().value().empty()) {
    std::fprintf(stderr, "storage_bench: %s holds models already; give it an empty database\n",
                 (*store)->describe().c_str());
    return 1;
  }
  double bytes = 0;
  for (const auto& k : kinds) bytes += double(blobBytes(k));
  bytes = bytes / double(kinds.size()) * models;

  auto t = Clock::now();
  for (int i = 0; i < models; ++i) {
    model::ObjectModel m = model::cloneModel(kinds[size_t(i) % kinds.size()]);
    m.observations = {{absl::StrFormat("session%d", i / 100), uint32_t(i), Transform::Identity(),
                       Transform::Identity()}};
    const auto id = (*store)->addModel(std::move(m));
    if (!id.ok()) {
      std::fprintf(stderr, "storage_bench: %s\n", std::string(id.status().message()).c_str());
      return 1;
    }
  }
  const double insert_s = secondsSince(t);

  t = Clock::now();
  size_t points = 0;
  const auto ids = (*store)->modelIds().value();
  for (int64_t id : ids) points += (*store)->model(id).value()->cloud.points.size();
  const double load_s = secondsSince(t);
  store->reset();

  t = Clock::now();
  auto reopened = storage::openStore(path, options);
  const double open_s = secondsSince(t);
  if (!reopened.ok()) {
    std::fprintf(stderr, "storage_bench: %s\n", std::string(reopened.status().message()).c_str());
    return 1;
  }
  t = Clock::now();
  auto entries = (*reopened)->matchEntries(true).value();
  std::vector<model::Fpfh> all;
  for (const auto& e : entries.entries) all.insert(all.end(), e.descriptors.begin(), e.descriptors.end());
  const double entries_s = secondsSince(t);
  t = Clock::now();
  matching::DescriptorIndex index(all);
  const double index_s = secondsSince(t);
  const auto stats = (*reopened)->stats().value();

  // The prefilter as the database keeps it (core/database/prefilter_index.h): loaded once, then
  // one model put per insert, against a full rebuild of the one kd-tree per insert (before).
  database::PrefilterIndex prefilter;
  std::vector<std::pair<int64_t, std::vector<model::Fpfh>*>> loaded;  // load takes them
  for (auto& e : entries.entries) loaded.emplace_back(e.id, &e.descriptors);
  t = Clock::now();
  prefilter.load(loaded);
  const double prefilter_load_s = secondsSince(t);
  const int puts = 200;
  std::vector<double> put_ms;
  const size_t built_before = prefilter.rebuilt();
  for (int i = 0; i < puts; ++i) {
    t = Clock::now();
    prefilter.put(int64_t(ids.back()) + 1 + i, kinds[size_t(i) % kinds.size()].descriptors);
    put_ms.push_back(1000.0 * secondsSince(t));
  }
  std::vector<double> sorted = put_ms;
  std::sort(sorted.begin(), sorted.end());
  double put_total_ms = 0;
  for (const double ms : put_ms) put_total_ms += ms;
  // One insert's prefilter query: every descriptor of a chair, its nearest (the default
  // database.prefilter_neighbours), on the one tree and on the incremental index.
  const Params defaults;
  const auto& query = kinds.front().descriptors;
  const int k = defaults.database.prefilter_neighbours;
  t = Clock::now();
  for (const auto& d : query) (void)index.nearest(d, k);
  const double query_tree_ms = 1000.0 * secondsSince(t);
  t = Clock::now();
  for (const auto& d : query) (void)prefilter.nearest(d, k);
  const double query_prefilter_ms = 1000.0 * secondsSince(t);

  std::printf("\n%d models in %s, %s, %.1f MB\n", models, (*reopened)->describe().c_str(),
              own_file || !storage::isPostgresTarget(path)
                  ? absl::StrFormat("synchronous=%s", synchronous).c_str()
                  : "PostgreSQL",
              double(stats.file_bytes) / 1e6);
  std::printf("%-44s %10s %10s %10s\n", "", "seconds", "models/s", "MB/s");
  std::printf("%-44s %10.2f %10.1f %10.1f\n", "insert (one transaction each, encode incl.)",
              insert_s, models / insert_s, bytes / 1e6 / insert_s);
  std::printf("%-44s %10.2f %10.1f %10.1f\n", "load every model (decode incl.)", load_s,
              models / load_s, bytes / 1e6 / load_s);
  std::printf("%-44s %10.3f\n", "open (schema check; SQLite: quick_check)", open_s);
  std::printf("%-44s %10.3f   (%zu descriptors)\n", "matcher index: read descriptors", entries_s,
              all.size());
  std::printf("%-44s %10.3f\n", "matcher index: build the kd-tree", index_s);
  std::printf("\nprefilter, %zu models loaded, then %d more put one at a time (one per insert)\n",
              entries.entries.size(), puts);
  std::printf("%-44s %10.3f\n", "load (one tree, at open)", prefilter_load_s);
  std::printf("%-44s %10.2f ms median, %.2f p99, %.2f max, %.2f mean\n", "put one model",
              sorted[sorted.size() / 2], sorted[size_t(0.99 * double(sorted.size() - 1))],
              sorted.back(), put_total_ms / puts);
  std::printf("%-44s %10.1f   (descriptors per put; a full rebuild per insert: %zu)\n",
              "  kd-tree work", double(prefilter.rebuilt() - built_before) / puts, all.size());
  std::printf("%-44s %10zu\n", "  trees after the puts", prefilter.trees());
  std::printf("%-44s %10.2f ms one tree, %.2f incremental (%zu descriptors, k %d)\n",
              "one insert's query", query_tree_ms, query_prefilter_ms, query.size(), k);
  std::printf("(%zu points loaded)\n", points);
  return 0;
}
