// Private to storage/sqlite/: what the files of SqliteStore's implementation share (the time
// expression of every row, a statement's row for the row readers, the reader lease). Not
// included outside storage/sqlite/.
#pragma once

#include <cstdint>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/common/status.h"
#include "storage/sqlite/sqlite_store.h"
#include "storage/sqlite/sqlite_util.h"

namespace objdb::storage {
namespace internal {

// SQL for "now" as the rows keep times: ISO-8601 UTC with milliseconds.
inline constexpr const char* kNow = "strftime('%Y-%m-%dT%H:%M:%fZ','now')";

// The current row of a statement, for the row readers of storage/row_codec.h.
class StatementRow final : public Row {
 public:
  explicit StatementRow(const Statement& statement) : statement_(statement) {}
  bool isNull(int column) const override { return statement_.columnIsNull(column); }
  int64_t integer(int column) const override { return statement_.columnInt(column); }
  double real(int column) const override { return statement_.columnDouble(column); }
  std::string text(int column) const override { return statement_.columnText(column); }
  std::string_view bytes(int column) const override { return statement_.columnBlob(column); }

 private:
  const Statement& statement_;
};

}  // namespace internal

// A reader connection borrowed from the pool, given back when the lease ends.
class SqliteStore::ReaderLease {
 public:
  ReaderLease(const SqliteStore* store, Connection connection)
      : store_(store), connection_(std::move(connection)) {}
  ReaderLease(ReaderLease&& other) noexcept
      : store_(other.store_), connection_(std::move(other.connection_)) {
    other.store_ = nullptr;
    other.connection_.reset();
  }
  ReaderLease& operator=(ReaderLease&&) = delete;
  ~ReaderLease() {
    if (!connection_ || connection_->get() == nullptr || store_ == nullptr) return;
    std::lock_guard lock(store_->reader_mutex_);
    if (store_->idle_readers_.size() < size_t(store_->options_.max_readers)) {
      store_->idle_readers_.push_back(std::move(*connection_));
    }
  }
  const Connection& operator*() const { return *connection_; }

 private:
  const SqliteStore* store_;
  std::optional<Connection> connection_;
};

}  // namespace objdb::storage
