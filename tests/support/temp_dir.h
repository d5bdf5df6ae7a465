// A fresh temporary directory per test, removed when the object goes out of scope.
#pragma once

#include <filesystem>
#include <string>

namespace objdb::testing {

class TempDir {
 public:
  TempDir();
  ~TempDir();
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

// Writes `text` to `path` (creating parent folders); returns false on failure.
bool writeTextFile(const std::filesystem::path& path, const std::string& text);

}  // namespace objdb::testing
