// Shared helpers of the objdb subcommands: strict integer options and uniform error output
// ("objdb <command>: message"; usage errors exit 2, runtime errors exit 1).
#pragma once

#include <string>

#include "core/common/status.h"

namespace objdb::cli {

// Parses a whole decimal integer within [lo, hi]; false on anything else.
bool parseInt(const char* text, long long lo, long long hi, long long* out);

// Prints "objdb <command>: <message>", a blank line and `usage` to stderr; returns 2.
int usageError(const char* command, const std::string& message, const char* usage);

// Prints "objdb <command>: <status message>" to stderr; returns 1.
int reportError(const char* command, const Status& status);

}  // namespace objdb::cli
