// The Store conformance suite (store_conformance.h), part 3: session leases, which several
// servers on one database use to own their sessions (one holder at a time, until the lease
// expires or its holder gives it up).
#include <chrono>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "tests/storage/store_conformance.h"

namespace objdb::storage {
namespace {

using objdb::testing::StoreConformance;
using ::testing::ElementsAre;
using ::testing::IsEmpty;
using namespace std::chrono_literals;

TEST_P(StoreConformance, ALeaseHasOneHolderUntilItIsGivenUp) {
  auto store = open(freshTarget());
  ASSERT_NE(store, nullptr);
  // A lease may come before its session's row: a server leases a name, then creates it.
  EXPECT_EQ(store->acquireLease("monday", "a", 30s).value(), "a");
  EXPECT_EQ(store->acquireLease("monday", "b", 30s).value(), "a");  // held: the holder answers
  EXPECT_EQ(store->acquireLease("monday", "a", 30s).value(), "a");  // the holder renews
  EXPECT_EQ(store->acquireLease("tuesday", "b", 30s).value(), "b");
  EXPECT_THAT(store->renewLeases("a", 30s).value(), ElementsAre("monday"));
  EXPECT_THAT(store->renewLeases("b", 30s).value(), ElementsAre("tuesday"));
  EXPECT_THAT(store->renewLeases("c", 30s).value(), IsEmpty());
  // Only the holder gives it up.
  ASSERT_TRUE(store->releaseLease("monday", "b").ok());
  EXPECT_EQ(store->acquireLease("monday", "b", 30s).value(), "a");
  ASSERT_TRUE(store->releaseLease("monday", "a").ok());
  EXPECT_THAT(store->renewLeases("a", 30s).value(), IsEmpty());
  EXPECT_EQ(store->acquireLease("monday", "b", 30s).value(), "b");
  ASSERT_TRUE(store->releaseLease("nobody's", "a").ok());  // nothing to give up: fine
  // A holder must have a name.
  EXPECT_EQ(store->acquireLease("wednesday", "", 30s).status().code(),
            absl::StatusCode::kInvalidArgument);
}

TEST_P(StoreConformance, AnExpiredLeaseIsNotRenewedAndGoesToTheNextServerThatAsks) {
  auto store = open(freshTarget());
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(store->acquireLease("monday", "a", 300ms).value(), "a");
  EXPECT_EQ(store->acquireLease("tuesday", "a", 30s).value(), "a");
  EXPECT_EQ(store->acquireLease("monday", "b", 30s).value(), "a");  // not expired yet
  std::this_thread::sleep_for(600ms);
  // Its holder cannot renew an expired lease: another server may have it by now.
  EXPECT_THAT(store->renewLeases("a", 30s).value(), ElementsAre("tuesday"));
  EXPECT_EQ(store->acquireLease("monday", "b", 30s).value(), "b");
  EXPECT_EQ(store->acquireLease("monday", "a", 30s).value(), "b");
  EXPECT_EQ(store->acquireLease("tuesday", "b", 30s).value(), "a");  // renewed, still a's
}

// Whether another server is at work on the database: someone else holds a live lease.
TEST_P(StoreConformance, OthersHoldLeasesWhileAnotherHolderHasOneThatHasNotExpired) {
  auto store = open(freshTarget());
  ASSERT_NE(store, nullptr);
  EXPECT_FALSE(store->othersHoldLeases("a").value());
  EXPECT_EQ(store->acquireLease("monday", "a", 30s).value(), "a");
  EXPECT_FALSE(store->othersHoldLeases("a").value()) << "its own leases are not others'";
  EXPECT_TRUE(store->othersHoldLeases("b").value());
  EXPECT_EQ(store->acquireLease("tuesday", "b", 300ms).value(), "b");
  EXPECT_TRUE(store->othersHoldLeases("a").value());
  std::this_thread::sleep_for(600ms);
  EXPECT_FALSE(store->othersHoldLeases("a").value()) << "b's lease expired";
  ASSERT_TRUE(store->releaseLease("monday", "a").ok());
  EXPECT_FALSE(store->othersHoldLeases("b").value());
}

}  // namespace
}  // namespace objdb::storage
