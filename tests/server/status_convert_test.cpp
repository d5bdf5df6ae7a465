// absl::Status → grpc::Status: every code maps to the same google.rpc.Code, messages are capped.
#include "server/status_convert.h"

#include <gtest/gtest.h>

#include <string>

namespace objdb {
namespace {

TEST(StatusConvert, EveryAbslCodeMapsToTheGrpcCodeWithTheSameNumber) {
  for (int code = 1; code <= 16; ++code) {
    const auto absl_code = static_cast<absl::StatusCode>(code);
    const grpc::Status converted = toGrpcStatus(Status(absl_code, "what went wrong"));
    EXPECT_EQ(static_cast<int>(converted.error_code()), code)
        << absl::StatusCodeToString(absl_code);
    EXPECT_EQ(converted.error_message(), "what went wrong");
  }
  EXPECT_EQ(toGrpcStatus(absl::InvalidArgumentError("x")).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_EQ(toGrpcStatus(absl::DataLossError("x")).error_code(), grpc::StatusCode::DATA_LOSS);
  EXPECT_EQ(toGrpcStatus(absl::UnauthenticatedError("x")).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
}

TEST(StatusConvert, OkBecomesOkWithoutMessage) {
  const grpc::Status converted = toGrpcStatus(absl::OkStatus());
  EXPECT_TRUE(converted.ok());
  EXPECT_EQ(converted.error_message(), "");
}

TEST(StatusConvert, CodeUnknownToTheSwitchBecomesUnknown) {
  const grpc::Status converted = toGrpcStatus(Status(static_cast<absl::StatusCode>(99), "x"));
  EXPECT_EQ(converted.error_code(), grpc::StatusCode::UNKNOWN);
}

TEST(StatusConvert, MessagesUpTo1024BytesPassUnchanged) {
  const std::string exactly(kMaxStatusMessageBytes, 'a');
  EXPECT_EQ(toGrpcStatus(absl::NotFoundError(exactly)).error_message(), exactly);
}

TEST(StatusConvert, LongMessagesAreCutTo1024BytesEndingInEllipsis) {
  const std::string message = "object 17: " + std::string(5000, 'x');
  const std::string capped = toGrpcStatus(absl::InternalError(message)).error_message();
  EXPECT_EQ(capped.size(), kMaxStatusMessageBytes);
  EXPECT_EQ(capped.substr(capped.size() - 3), "...");
  EXPECT_EQ(capped.substr(0, 11), "object 17: ");
}

TEST(StatusConvert, CapNeverSplitsAUtf8Character) {
  std::string message;
  for (int i = 0; i < 1000; ++i) message += "\xC3\xA9";  // "é", 2 bytes
  const std::string capped = capStatusMessage(message, 1024);
  ASSERT_LE(capped.size(), 1024u);
  ASSERT_EQ(capped.substr(capped.size() - 3), "...");
  const std::string body = capped.substr(0, capped.size() - 3);
  EXPECT_EQ(body.size(), 1020u);  // 1021 would end inside a character
  EXPECT_EQ(body, message.substr(0, 1020));
}

TEST(StatusConvert, TinyCapsStillReturnSomethingBounded) {
  EXPECT_EQ(capStatusMessage("abcdef", 2), "..");
  EXPECT_EQ(capStatusMessage("abcdef", 4), "a...");
  EXPECT_EQ(capStatusMessage("abc", 3), "abc");
}

}  // namespace
}  // namespace objdb
