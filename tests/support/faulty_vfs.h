// A fault-injecting SQLite VFS for the I/O-error tests, our own code after
// SQLite's technique: it wraps the platform's default VFS, counts the write, sync and truncate
// calls made on every file SQLite opens (database, WAL, journal), and fails the k-th one once or
// from then on. A size cap emulates a full disk, per file: a write that ends past the cap in any
// one file fails with SQLITE_FULL (it is not a budget shared by the files).
//
// While a FaultyVfs object lives, it is SQLite's default VFS, so every connection opened in that
// time goes through it; the destructor restores the previous default. Close the connections
// opened through it before it goes out of scope. One at a time per process. Change the plan
// (failAt, capFileBytes, lift) only while no connection is writing: the counters are atomic, but
// a plan change racing with a write may count or fail that write under either plan.
#pragma once

#include <cstdint>

namespace objdb::testing {

class FaultyVfs {
 public:
  enum Op : unsigned { kWrite = 1u, kSync = 2u, kTruncate = 4u, kAllOps = 7u };

  FaultyVfs();
  ~FaultyVfs();
  FaultyVfs(const FaultyVfs&) = delete;
  FaultyVfs& operator=(const FaultyVfs&) = delete;

  // Restarts the count at 0 and fails the k-th (1-based) operation in `ops` from now on: only
  // that one, or every one from it on when `persistent`. k ≤ 0 only counts.
  void failAt(int64_t k, bool persistent, unsigned ops = kAllOps);
  // Writes that end past `bytes` in a file fail with SQLITE_FULL (< 0: no cap).
  void capFileBytes(int64_t bytes);
  // No more faults and no cap; the counts stay readable.
  void lift();

  int64_t operations() const;  // operations in the chosen set since the last failAt
  int64_t failures() const;    // operations failed since the last failAt or capFileBytes
};

}  // namespace objdb::testing
