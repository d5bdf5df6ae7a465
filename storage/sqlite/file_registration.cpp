#include "storage/sqlite/file_registration.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <map>
#include <mutex>
#include <utility>

#include "absl/strings/str_format.h"

namespace objdb::storage {
namespace {

// The database files this process's stores have open, by (device, inode).
struct OpenFile {
  int fd = -1;       // the one descriptor of the file this process opens itself
  int stores = 0;    // registered stores
  bool writer = false;
};
std::mutex g_files_mutex;
std::map<std::pair<uint64_t, uint64_t>, OpenFile> g_files;

Status heldByAnotherWriter(const std::string& path) {
  return absl::FailedPreconditionError(absl::StrFormat(
      "%s is open for writing by another objdb store (objdb-server or objdb ingest, in this "
      "process or another); one writer at a time (readers such as `objdb db` may open it "
      "meanwhile)",
      path));
}

}  // namespace

StatusOr<FileRegistration> FileRegistration::acquire(const std::string& path, bool writer) {
  std::lock_guard lock(g_files_mutex);
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    return absl::UnavailableError(absl::StrFormat("%s: %s", path, std::strerror(errno)));
  }
  const std::pair<uint64_t, uint64_t> key{uint64_t(st.st_dev), uint64_t(st.st_ino)};
  auto it = g_files.find(key);
  if (it == g_files.end()) {
    // No store of this process has the file open: no SQLite lock of ours can be dropped by
    // closing this descriptor should the lock below fail.
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
      return absl::UnavailableError(
          absl::StrFormat("opening %s: %s", path, std::strerror(errno)));
    }
    if (writer && ::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      ::close(fd);
      if (error == EWOULDBLOCK) return heldByAnotherWriter(path);
      return absl::UnavailableError(absl::StrFormat("locking %s: %s", path, std::strerror(error)));
    }
    g_files[key] = OpenFile{fd, 1, writer};
    return FileRegistration(key.first, key.second, writer);
  }
  OpenFile& file = it->second;
  if (writer) {
    if (file.writer) return heldByAnotherWriter(path);
    if (::flock(file.fd, LOCK_EX | LOCK_NB) != 0) {
      const int error = errno;
      if (error == EWOULDBLOCK) return heldByAnotherWriter(path);
      return absl::UnavailableError(absl::StrFormat("locking %s: %s", path, std::strerror(error)));
    }
    file.writer = true;
  }
  ++file.stores;
  return FileRegistration(key.first, key.second, writer);
}

FileRegistration::FileRegistration(FileRegistration&& other) noexcept
    : device_(other.device_), inode_(other.inode_), writer_(other.writer_),
      active_(other.active_) {
  other.active_ = false;
}

FileRegistration::~FileRegistration() {
  if (!active_) return;
  std::lock_guard lock(g_files_mutex);
  const auto it = g_files.find({device_, inode_});
  if (it == g_files.end()) return;
  OpenFile& file = it->second;
  if (writer_) {
    ::flock(file.fd, LOCK_UN);  // unlocking keeps the descriptor: no SQLite lock is dropped
    file.writer = false;
  }
  if (--file.stores == 0) {
    ::close(file.fd);  // the last store of this file: its connections are closed already
    g_files.erase(it);
  }
}

}  // namespace objdb::storage
