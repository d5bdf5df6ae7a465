// The file steps both backends' backups share (SqliteStore::backupTo, PostgresStore::backupTo): a
// copy is written under a temporary name, synced, linked to its name (link() never replaces a file
// that appeared there meanwhile), and then its directory is synced.
#pragma once

#include <string>

#include "core/common/status.h"

namespace objdb::storage {

// fsync of the file or directory at `path`; best effort (nothing when it cannot be opened).
void syncPath(const std::string& path);
// Syncs the directory `path` is in: a new name there survives a power loss only then.
void syncDirectoryOf(const std::string& path);
// The error of a link() or rename() that could not give the copy its name `path` (`error`: its
// errno): ALREADY_EXISTS when a file appeared there meanwhile (it is left alone), else UNAVAILABLE.
Status backupNamingError(const std::string& path, int error);

}  // namespace objdb::storage
