// Every SqliteStore's hold on its database file, process-wide: one writer per file (an advisory
// flock), and one descriptor per file shared by all of the process's stores, so that closing a
// store never drops another store's SQLite locks.
#pragma once

#include <cstdint>
#include <string>

#include "core/common/status.h"

namespace objdb::storage {

// One writer per file: a writable store takes an advisory lock (flock) on the file. POSIX drops
// a process's fcntl locks on a file — SQLite's — when any descriptor of that file is closed, so
// the process keeps one descriptor per file, shared by all its stores (read-only ones too), and
// closes it only when the last of them has closed its connections.
class FileRegistration {
 public:
  // Registers a store of `path` (which must exist); `writer`: also takes the writer lock.
  // FAILED_PRECONDITION when another writer (in this process or another) holds it.
  static StatusOr<FileRegistration> acquire(const std::string& path, bool writer);
  FileRegistration(FileRegistration&& other) noexcept;
  FileRegistration& operator=(FileRegistration&&) = delete;
  FileRegistration(const FileRegistration&) = delete;
  ~FileRegistration();

 private:
  FileRegistration(uint64_t device, uint64_t inode, bool writer)
      : device_(device), inode_(inode), writer_(writer), active_(true) {}
  uint64_t device_ = 0, inode_ = 0;
  bool writer_ = false;
  bool active_ = false;
};

}  // namespace objdb::storage
