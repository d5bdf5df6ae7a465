// The PostgreSQL cluster of the POSTGRES tests: its URI and a fresh, empty database per test.
// CTest's fixture postgres_cluster starts the cluster (scripts/pg_test_cluster.sh) and sets
// OBJDB_TEST_POSTGRES_DIR; databases are left behind, the whole cluster is thrown away after.
#pragma once

#include <string>

#include "core/common/status.h"

namespace objdb::testing {

// The libpq URI of the test cluster's maintenance database (from $OBJDB_TEST_POSTGRES_DIR/uri);
// FAILED_PRECONDITION, saying how to start the cluster, when it is not set or not running.
StatusOr<std::string> postgresClusterUri();

// A new, empty database in the test cluster (CREATE DATABASE named hint_pid_counter, lowercase
// letters, digits and '_') and its URI: the cluster URI with that database name.
StatusOr<std::string> freshPostgresDatabase(const std::string& name_hint);

// `uri` (postgresql://...) with its database name (the path) replaced by `dbname`, the query
// string kept: postgresql://u@/postgres?host=/tmp/x → postgresql://u@/DBNAME?host=/tmp/x.
// A keyword/value conninfo string gets dbname='DBNAME' appended instead.
std::string postgresUriWithDatabase(const std::string& uri, const std::string& dbname);

}  // namespace objdb::testing
