// MergeRecord::source is written and read by one pair of functions: what the database writes,
// GetObject reads back (session names may hold '/'-free dots and dashes; the label is the last
// field), and anything else is refused.
#include "core/database/merge_source.h"

#include <gtest/gtest.h>

namespace objdb::database {
namespace {

TEST(MergeSource, SegmentAndModelSourcesReadBackAndOthersAreRefused) {
  std::string session;
  gsm::Label label = 0;
  EXPECT_EQ(segmentSource("session_2", 88), "segment session_2/88");
  ASSERT_TRUE(parseSegmentSource(segmentSource("lab.replaced-1", 7), &session, &label));
  EXPECT_EQ(session, "lab.replaced-1");
  EXPECT_EQ(label, 7u);
  int64_t id = 0;
  EXPECT_EQ(modelSource(42), "model 42");
  ASSERT_TRUE(parseModelSource(modelSource(42), &id));
  EXPECT_EQ(id, 42);
  EXPECT_FALSE(parseSegmentSource(modelSource(42), &session, &label));
  EXPECT_FALSE(parseModelSource(segmentSource("s", 1), &id));
  EXPECT_FALSE(parseSegmentSource("segment /3", &session, &label));
  EXPECT_FALSE(parseSegmentSource("segment s/x", &session, &label));
  EXPECT_FALSE(parseModelSource("model 0", &id));
}

}  // namespace
}  // namespace objdb::database
