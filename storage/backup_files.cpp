#include "storage/backup_files.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "absl/strings/str_format.h"

namespace objdb::storage {

void syncPath(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

void syncDirectoryOf(const std::string& path) {
  const std::string directory = std::filesystem::path(path).parent_path().string();
  syncPath(directory.empty() ? "." : directory);
}

Status backupNamingError(const std::string& path, int error) {
  if (error == EEXIST) {
    return absl::AlreadyExistsError(
        absl::StrFormat("backup: %s appeared while the copy was made; it was left alone", path));
  }
  return absl::UnavailableError(
      absl::StrFormat("backup: naming the copy %s: %s", path, std::strerror(error)));
}

}  // namespace objdb::storage
