#include "tests/support/faulty_vfs.h"

#include <sqlite3.h>

#include <atomic>
#include <cstdlib>
#include <cstring>

namespace objdb::testing {
namespace {

struct FaultState {
  std::atomic<int64_t> operations{0};
  std::atomic<int64_t> fail_at{0};
  std::atomic<bool> persistent{false};
  std::atomic<unsigned> ops{0};
  std::atomic<int64_t> failures{0};
  std::atomic<int64_t> cap_bytes{-1};
};

FaultState g_state;
sqlite3_vfs* g_real = nullptr;  // the default VFS we wrap
sqlite3_vfs g_vfs;              // ours: a copy of the real one with our xOpen
bool g_active = false;

// Our file: the real file's structure follows it in the same allocation (szOsFile).
struct FaultyFile {
  sqlite3_file base;
  sqlite3_file* real;
};
constexpr int kHeaderBytes = int((sizeof(FaultyFile) + 7) & ~size_t{7});

sqlite3_file* realOf(sqlite3_file* file) { return reinterpret_cast<FaultyFile*>(file)->real; }

// Whether this operation of kind `op` is the one (or one of those) to fail.
bool shouldFail(FaultyVfs::Op op) {
  if ((g_state.ops.load() & op) == 0) return false;
  const int64_t n = ++g_state.operations;
  const int64_t k = g_state.fail_at.load();
  if (k <= 0) return false;
  if (n == k || (g_state.persistent.load() && n > k)) {
    ++g_state.failures;
    return true;
  }
  return false;
}

int fileClose(sqlite3_file* f) {
  sqlite3_file* real = realOf(f);
  const int rc = real->pMethods->xClose(real);
  f->pMethods = nullptr;
  return rc;
}
int fileRead(sqlite3_file* f, void* buffer, int amount, sqlite3_int64 offset) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xRead(real, buffer, amount, offset);
}
int fileWrite(sqlite3_file* f, const void* buffer, int amount, sqlite3_int64 offset) {
  const int64_t cap = g_state.cap_bytes.load();
  if (cap >= 0 && offset + amount > cap) {
    ++g_state.failures;
    return SQLITE_FULL;
  }
  if (shouldFail(FaultyVfs::kWrite)) return SQLITE_IOERR_WRITE;
  sqlite3_file* real = realOf(f);
  return real->pMethods->xWrite(real, buffer, amount, offset);
}
int fileTruncate(sqlite3_file* f, sqlite3_int64 size) {
  if (shouldFail(FaultyVfs::kTruncate)) return SQLITE_IOERR_TRUNCATE;
  sqlite3_file* real = realOf(f);
  return real->pMethods->xTruncate(real, size);
}
int fileSync(sqlite3_file* f, int flags) {
  if (shouldFail(FaultyVfs::kSync)) return SQLITE_IOERR_FSYNC;
  sqlite3_file* real = realOf(f);
  return real->pMethods->xSync(real, flags);
}
int fileSize(sqlite3_file* f, sqlite3_int64* size) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xFileSize(real, size);
}
int fileLock(sqlite3_file* f, int level) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xLock(real, level);
}
int fileUnlock(sqlite3_file* f, int level) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xUnlock(real, level);
}
int fileCheckReservedLock(sqlite3_file* f, int* out) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xCheckReservedLock(real, out);
}
int fileControl(sqlite3_file* f, int op, void* arg) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xFileControl(real, op, arg);
}
int fileSectorSize(sqlite3_file* f) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xSectorSize(real);
}
int fileDeviceCharacteristics(sqlite3_file* f) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xDeviceCharacteristics(real);
}
int fileShmMap(sqlite3_file* f, int region, int size, int extend, void volatile** out) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xShmMap(real, region, size, extend, out);
}
int fileShmLock(sqlite3_file* f, int offset, int n, int flags) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xShmLock(real, offset, n, flags);
}
void fileShmBarrier(sqlite3_file* f) {
  sqlite3_file* real = realOf(f);
  real->pMethods->xShmBarrier(real);
}
int fileShmUnmap(sqlite3_file* f, int delete_flag) {
  sqlite3_file* real = realOf(f);
  return real->pMethods->xShmUnmap(real, delete_flag);
}
int fileFetch(sqlite3_file* f, sqlite3_int64 offset, int amount, void** out) {
  sqlite3_file* real = realOf(f);
  if (real->pMethods->iVersion < 3 || real->pMethods->xFetch == nullptr) {
    *out = nullptr;
    return SQLITE_OK;
  }
  return real->pMethods->xFetch(real, offset, amount, out);
}
int fileUnfetch(sqlite3_file* f, sqlite3_int64 offset, void* p) {
  sqlite3_file* real = realOf(f);
  if (real->pMethods->iVersion < 3 || real->pMethods->xUnfetch == nullptr) return SQLITE_OK;
  return real->pMethods->xUnfetch(real, offset, p);
}

// With shared memory (WAL) and memory-mapped reads, for real files that have them.
const sqlite3_io_methods kMethods = {
    3,                          fileClose,          fileRead,         fileWrite,
    fileTruncate,               fileSync,           fileSize,         fileLock,
    fileUnlock,                 fileCheckReservedLock, fileControl,   fileSectorSize,
    fileDeviceCharacteristics,  fileShmMap,         fileShmLock,      fileShmBarrier,
    fileShmUnmap,               fileFetch,          fileUnfetch};
// Without them: SQLite then knows that WAL is not possible on the file, as with the real one.
const sqlite3_io_methods kMethodsV1 = {
    1,                          fileClose,          fileRead,         fileWrite,
    fileTruncate,               fileSync,           fileSize,         fileLock,
    fileUnlock,                 fileCheckReservedLock, fileControl,   fileSectorSize,
    fileDeviceCharacteristics,  nullptr,            nullptr,          nullptr,
    nullptr,                    nullptr,            nullptr};

int vfsOpen(sqlite3_vfs*, sqlite3_filename name, sqlite3_file* file, int flags, int* out_flags) {
  auto* ours = reinterpret_cast<FaultyFile*>(file);
  ours->real = reinterpret_cast<sqlite3_file*>(reinterpret_cast<char*>(file) + kHeaderBytes);
  ours->real->pMethods = nullptr;
  const int rc = g_real->xOpen(g_real, name, ours->real, flags, out_flags);
  const sqlite3_io_methods* real_methods = ours->real->pMethods;
  if (rc != SQLITE_OK) {
    // SQLite expects no methods on a file that failed to open (it will not close it).
    if (real_methods != nullptr) real_methods->xClose(ours->real);
    ours->real->pMethods = nullptr;
    ours->base.pMethods = nullptr;
    return rc;
  }
  const bool shared_memory = real_methods != nullptr && real_methods->iVersion >= 2 &&
                             real_methods->xShmMap != nullptr;
  ours->base.pMethods =
      real_methods == nullptr ? nullptr : (shared_memory ? &kMethods : &kMethodsV1);
  return rc;
}

}  // namespace

FaultyVfs::FaultyVfs() {
  if (g_active) std::abort();  // one at a time
  g_real = sqlite3_vfs_find(nullptr);
  if (g_real == nullptr) std::abort();
  std::memcpy(&g_vfs, g_real, sizeof(g_vfs));
  g_vfs.zName = "objdb-faulty";
  g_vfs.pNext = nullptr;
  g_vfs.szOsFile = kHeaderBytes + g_real->szOsFile;
  g_vfs.xOpen = vfsOpen;
  g_state.operations = 0;
  g_state.fail_at = 0;
  g_state.persistent = false;
  g_state.ops = 0;
  g_state.failures = 0;
  g_state.cap_bytes = -1;
  if (sqlite3_vfs_register(&g_vfs, 1) != SQLITE_OK) std::abort();
  g_active = true;
}

FaultyVfs::~FaultyVfs() {
  sqlite3_vfs_unregister(&g_vfs);
  sqlite3_vfs_register(g_real, 1);
  g_active = false;
}

void FaultyVfs::failAt(int64_t k, bool persistent, unsigned ops) {
  g_state.ops = 0;  // nothing counts while the plan changes
  g_state.operations = 0;
  g_state.failures = 0;
  g_state.fail_at = k;
  g_state.persistent = persistent;
  g_state.ops = ops;
}

void FaultyVfs::capFileBytes(int64_t bytes) {
  g_state.failures = 0;
  g_state.cap_bytes = bytes;
}

void FaultyVfs::lift() {
  g_state.ops = 0;
  g_state.fail_at = 0;
  g_state.persistent = false;
  g_state.cap_bytes = -1;
}

int64_t FaultyVfs::operations() const { return g_state.operations.load(); }
int64_t FaultyVfs::failures() const { return g_state.failures.load(); }

}  // namespace objdb::testing
