// The Store conformance suite (store_conformance.h), part 3: what two-stage retrieval reads — a
// model's global descriptor stored with it, match entries without the local descriptors, the
// local descriptors of a short list, and global descriptors written back for older rows.
#include <vector>

#include <gtest/gtest.h>

#include "core/model/global_descriptor.h"
#include "tests/storage/store_conformance.h"
#include "tests/storage/store_fixtures.h"

namespace objdb::storage {
namespace {

using objdb::testing::makeStoreModel;
using objdb::testing::StoreConformance;

TEST_P(StoreConformance, GlobalDescriptorsAreStoredWithTheirModelAndReadWithoutTheLocalOnes) {
  const std::string target = freshTarget();
  std::vector<model::ObjectModel> models;
  {
    auto store = open(target);
    ASSERT_NE(store, nullptr);
    for (uint32_t seed : {3u, 4u, 6u}) {
      model::ObjectModel m = makeStoreModel(seed, 1);
      ASSERT_FALSE(m.descriptors.empty());
      m.id = store->addModel(model::cloneModel(m)).value();
      models.push_back(std::move(m));
    }
  }
  auto store = open(target);  // reopened: read from the file or server, not a cache
  ASSERT_NE(store, nullptr);
  const auto light = store->matchEntries(false);
  ASSERT_TRUE(light.ok()) << light.status();
  const auto full = store->matchEntries(true);
  ASSERT_TRUE(full.ok()) << full.status();
  ASSERT_EQ(light->entries.size(), 3u);
  ASSERT_EQ(full->entries.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const std::vector<float> expected = model::globalDescriptor(models[i].descriptors);
    EXPECT_EQ(light->entries[i].id, models[i].id);
    EXPECT_TRUE(light->entries[i].descriptors.empty()) << models[i].id;
    EXPECT_EQ(light->entries[i].global, expected) << models[i].id;
    EXPECT_EQ(light->entries[i].num_keypoints, models[i].keypoint_indices.size());
    EXPECT_EQ(full->entries[i].descriptors, models[i].descriptors) << models[i].id;
    EXPECT_EQ(full->entries[i].global, expected) << models[i].id;
  }
  // The local descriptors of a short list, in its order.
  const auto listed = store->descriptorsOf({models[2].id, models[0].id});
  ASSERT_TRUE(listed.ok()) << listed.status();
  ASSERT_EQ(listed->size(), 2u);
  EXPECT_EQ((*listed)[0], models[2].descriptors);
  EXPECT_EQ((*listed)[1], models[0].descriptors);
  // A replaced model's global descriptor follows its new descriptors; a removed model has none.
  model::ObjectModel replacement = makeStoreModel(9, 2);
  replacement.id = models[1].id;
  ASSERT_TRUE(store->replaceModel(model::cloneModel(replacement), std::nullopt).ok());
  ASSERT_TRUE(store->removeModel(models[2].id).ok());
  const auto after = store->matchEntries(false).value();
  ASSERT_EQ(after.entries.size(), 2u);
  EXPECT_EQ(after.entries[1].global, model::globalDescriptor(replacement.descriptors));
  const auto gone = store->descriptorsOf({models[0].id, models[2].id});
  EXPECT_EQ(gone.status().code(), absl::StatusCode::kNotFound) << gone.status();
  // Written back (as a database does for rows without one): read as written, the model's own
  // data untouched.
  const std::vector<float> other = model::globalDescriptor(replacement.descriptors);
  ASSERT_TRUE(store->putGlobalDescriptors({{models[0].id, other}}).ok());
  const auto rewritten = store->matchEntries(true).value();
  EXPECT_EQ(rewritten.entries[0].global, other);
  EXPECT_EQ(rewritten.entries[0].descriptors, models[0].descriptors);
}

}  // namespace
}  // namespace objdb::storage
