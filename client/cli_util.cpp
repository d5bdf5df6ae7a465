#include "client/cli_util.h"

#include <cerrno>
#include <cstdio>
#include <cstdlib>

namespace objdb::cli {

bool parseInt(const char* text, long long lo, long long hi, long long* out) {
  char* end = nullptr;
  errno = 0;
  const long long v = std::strtoll(text, &end, 10);
  if (errno != 0 || end == text || *end != '\0' || v < lo || v > hi) return false;
  *out = v;
  return true;
}

int usageError(const char* command, const std::string& message, const char* usage) {
  std::fprintf(stderr, "objdb %s: %s\n\n%s", command, message.c_str(), usage);
  return 2;
}

int reportError(const char* command, const Status& status) {
  std::fprintf(stderr, "objdb %s: %s\n", command, std::string(status.message()).c_str());
  return 1;
}

}  // namespace objdb::cli
