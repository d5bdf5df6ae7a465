// Error handling across module boundaries: absl::Status / absl::StatusOr<T> plus two macros.
// No exception escapes a module; third-party exceptions are caught at the call site.
#pragma once

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace objdb {

using absl::Status;
using absl::StatusOr;

#define OBJDB_STATUS_CONCAT_INNER_(a, b) a##b
#define OBJDB_STATUS_CONCAT_(a, b) OBJDB_STATUS_CONCAT_INNER_(a, b)

// Returns from the enclosing function if `expr` (a Status) is not OK.
#define OBJDB_RETURN_IF_ERROR(expr)              \
  do {                                           \
    ::absl::Status objdb_status_ = (expr);       \
    if (!objdb_status_.ok()) return objdb_status_; \
  } while (false)

// `OBJDB_ASSIGN_OR_RETURN(auto x, f());` assigns the value of a StatusOr or returns its error.
#define OBJDB_ASSIGN_OR_RETURN(lhs, expr)                                              \
  OBJDB_ASSIGN_OR_RETURN_IMPL_(OBJDB_STATUS_CONCAT_(objdb_statusor_, __LINE__), lhs, expr)
#define OBJDB_ASSIGN_OR_RETURN_IMPL_(tmp, lhs, expr) \
  auto tmp = (expr);                                 \
  if (!tmp.ok()) return tmp.status();                \
  lhs = std::move(tmp).value()

// Prefixes a status message with context ("reading poses.txt: ...") keeping its code.
inline Status annotate(const Status& status, absl::string_view context) {
  if (status.ok()) return status;
  return Status(status.code(), absl::StrCat(context, ": ", status.message()));
}

}  // namespace objdb
