// libFuzzer entry point of one target, chosen at compile time (OBJDB_FUZZ_TARGET = frame, blob
// or config; see tests/fuzz/CMakeLists.txt and scripts/fuzz.sh).
#include <cstddef>
#include <cstdint>

#include <google/protobuf/stubs/logging.h>

#include "tests/fuzz/fuzz_targets.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  google::protobuf::SetLogHandler(nullptr);  // parse errors of hostile bytes are expected
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  (void)objdb::fuzz::OBJDB_FUZZ_TARGET(data, size);
  return 0;
}
