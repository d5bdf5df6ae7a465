// The Store conformance suite (store_conformance.h) against PostgresStore: every store a new,
// empty database in the throwaway cluster of tests/support/postgres_test_cluster.h.
#include <gtest/gtest.h>

#include "tests/storage/store_conformance.h"
#include "tests/support/postgres_test_cluster.h"

namespace objdb::testing {
namespace {

INSTANTIATE_TEST_SUITE_P(Postgres, StoreConformance,
                         ::testing::Values(StoreBackend{
                             "Postgres", [] { return freshPostgresDatabase("conformance"); }}),
                         storeBackendName);

}  // namespace
}  // namespace objdb::testing
