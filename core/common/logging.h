// One named spdlog logger per module ("sim", "io", "server", ...), created on first use.
#pragma once

#include <memory>
#include <string>

#include <spdlog/spdlog.h>

namespace objdb {

// Returns the logger `name`, creating a stderr logger the first time. Thread-safe.
std::shared_ptr<spdlog::logger> logger(const std::string& name);

// Sets the level of every objdb logger, existing and future ("trace".."off"). Returns false
// for an unknown level name.
bool setLogLevel(const std::string& level);

}  // namespace objdb
