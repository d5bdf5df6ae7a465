// Authentication and transport security: token files, the bearer check, the
// listen policy, and over loopback: every objdb.v1.ObjectDatabase method (enumerated from the
// service descriptor, so a new RPC cannot skip the check) refuses a missing or wrong token;
// health stays open; TLS refuses plaintext clients and clients trusting another CA; mutual TLS
// refuses clients without a certificate of the client CA. Certificates are made with the
// openssl command-line tool (installed by scripts/deps.sh).
#include "server/auth.h"

#include <google/protobuf/descriptor.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <future>
#include <memory>
#include <string>
#include <vector>

#include "grpc/health/v1/health.grpc.pb.h"
#include "objdb/v1/objdb.grpc.pb.h"
#include "server/server.h"
#include "tests/server/loopback_server.h"
#include "tests/support/test_pki.h"
#include "tests/support/temp_dir.h"

namespace objdb {
namespace {

using testing::loopbackOptions;
using testing::startOrDie;
using testing::TempDir;
using testing::TestPki;
using testing::writeTextFile;

constexpr char kToken[] = "0123456789abcdef-objdb-test-token";

bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// --- token files and the bearer check ---------------------------------------------------------

TEST(TokenFile, ContentWithoutSurroundingWhitespaceIsTheToken) {
  TempDir dir;
  ASSERT_TRUE(writeTextFile(dir / "t", std::string("  ") + kToken + "\n"));
  const StatusOr<std::string> token = auth::readTokenFile((dir / "t").string());
  ASSERT_TRUE(token.ok()) << token.status();
  EXPECT_EQ(*token, kToken);
}

TEST(TokenFile, BadFilesAreClearErrorsThatNeverQuoteTheContent) {
  TempDir dir;
  const std::string secret_but_short = "s3cr3t";
  ASSERT_TRUE(writeTextFile(dir / "short", secret_but_short));
  ASSERT_TRUE(writeTextFile(dir / "empty", ""));
  ASSERT_TRUE(writeTextFile(dir / "blank", " \n\t\n"));
  ASSERT_TRUE(writeTextFile(dir / "space", "0123456789abcdef 0123456789abcdef"));
  ASSERT_TRUE(writeTextFile(dir / "long", std::string(auth::kMaxTokenChars + 1, 'x')));
  struct Case {
    std::string file, says;
    absl::StatusCode code;
  };
  for (const Case& c : std::vector<Case>{
           {"missing", "cannot be opened", absl::StatusCode::kNotFound},
           {"short", "holds 6 characters", absl::StatusCode::kInvalidArgument},
           {"empty", "is empty", absl::StatusCode::kInvalidArgument},
           {"blank", "holds 0 characters", absl::StatusCode::kInvalidArgument},
           {"space", "printable ASCII without spaces", absl::StatusCode::kInvalidArgument},
           {"long", "holds 4097 characters", absl::StatusCode::kInvalidArgument}}) {
    const std::string path = (dir / c.file).string();
    const StatusOr<std::string> token = auth::readTokenFile(path);
    ASSERT_FALSE(token.ok()) << c.file;
    EXPECT_EQ(token.status().code(), c.code) << c.file;
    const std::string message(token.status().message());
    EXPECT_TRUE(contains(message, path)) << message;
    EXPECT_TRUE(contains(message, c.says)) << message;
    EXPECT_FALSE(contains(message, secret_but_short)) << message;
    EXPECT_FALSE(contains(message, "0123456789abcdef")) << message;
  }
}

TEST(ConstantTimeEquals, ComparesWholeStrings) {
  EXPECT_TRUE(auth::constantTimeEquals("", ""));
  EXPECT_TRUE(auth::constantTimeEquals(kToken, kToken));
  EXPECT_FALSE(auth::constantTimeEquals(kToken, std::string(kToken) + "x"));
  EXPECT_FALSE(auth::constantTimeEquals(std::string(kToken) + "x", kToken));
  EXPECT_FALSE(auth::constantTimeEquals("abc", "abd"));
  EXPECT_FALSE(auth::constantTimeEquals("abc", ""));
  EXPECT_FALSE(auth::constantTimeEquals(std::string("ab\0", 3), "ab"));
}

TEST(CheckBearer, OnlyTheExactBearerTokenPasses) {
  const std::string token = kToken;
  const std::string right = "Bearer " + token;
  EXPECT_TRUE(auth::checkBearer(token, &right).ok());
  EXPECT_TRUE(auth::checkBearer("", nullptr).ok()) << "no token configured: open";
  const Status missing = auth::checkBearer(token, nullptr);
  EXPECT_EQ(missing.code(), absl::StatusCode::kUnauthenticated);
  EXPECT_TRUE(contains(std::string(missing.message()), "authorization: Bearer")) << missing;
  const std::string lower_case_scheme = "bearer " + token;
  EXPECT_TRUE(auth::checkBearer(token, &lower_case_scheme).ok()) << "RFC 7235: any case";
  for (const std::string& wrong :
       {std::string("Bearer ") + token + "x", token, "Bearer  " + token, "Bearer" + token,
        std::string("BEARER ") + std::string(token.size(), 'x'),
        std::string("Basic ") + token, std::string("Bearer "), std::string("")}) {
    const Status s = auth::checkBearer(token, &wrong);
    EXPECT_EQ(s.code(), absl::StatusCode::kUnauthenticated) << wrong;
    EXPECT_FALSE(contains(std::string(s.message()), token)) << s;
  }
}

// --- the listen policy --------------------------------------------------------------------

TEST(ServerOptionsAuth, ANonLoopbackAddressNeedsTlsAndAuthenticationOrTheOverride) {
  ServerOptions o = loopbackOptions();
  o.listen_address = "0.0.0.0:0";
  o.token_file = "token";  // validate() does not read files
  Status s = o.validate();
  EXPECT_FALSE(s.ok());
  EXPECT_TRUE(contains(std::string(s.message()), "no TLS")) << s;
  o.tls_cert_file = "cert.pem";
  o.tls_key_file = "key.pem";
  EXPECT_TRUE(o.validate().ok()) << o.validate();  // TLS + token
  o.token_file.clear();
  s = o.validate();
  EXPECT_FALSE(s.ok());
  EXPECT_TRUE(contains(std::string(s.message()), "no token and no client certificates")) << s;
  o.tls_client_ca_file = "ca.pem";
  EXPECT_TRUE(o.validate().ok()) << o.validate();  // mutual TLS
  ServerOptions plain = loopbackOptions();
  plain.listen_address = "0.0.0.0:0";
  plain.allow_remote = true;
  EXPECT_TRUE(plain.validate().ok()) << "the explicit override";
}

TEST(ServerOptionsAuth, TlsFilesGoTogether) {
  ServerOptions o = loopbackOptions();
  o.tls_cert_file = "cert.pem";
  EXPECT_TRUE(contains(std::string(o.validate().message()), "--tls-cert with --tls-key"));
  o = loopbackOptions();
  o.tls_key_file = "key.pem";
  EXPECT_TRUE(contains(std::string(o.validate().message()), "--tls-cert with --tls-key"));
  o = loopbackOptions();
  o.tls_client_ca_file = "ca.pem";
  EXPECT_TRUE(contains(std::string(o.validate().message()), "needs the server's own certificate"));
}

TEST(ServerOptionsAuth, AnUnreadableTokenFileRefusesTheStart) {
  TempDir dir;
  ServerOptions o = loopbackOptions();
  o.token_file = (dir / "absent").string();
  const auto server = ObjdbServer::start(o);
  ASSERT_FALSE(server.ok());
  EXPECT_EQ(server.status().code(), absl::StatusCode::kNotFound);
  EXPECT_TRUE(contains(std::string(server.status().message()), o.token_file)) << server.status();
}

// --- calls over loopback --------------------------------------------------------------------

// Every method of objdb.v1.ObjectDatabase, as "/objdb.v1.ObjectDatabase/Name".
std::vector<std::string> serviceMethods() {
  const google::protobuf::ServiceDescriptor* service =
      google::protobuf::DescriptorPool::generated_pool()->FindServiceByName(
          kObjectDatabaseServiceName);
  std::vector<std::string> methods;
  if (service == nullptr) return methods;
  for (int i = 0; i < service->method_count(); ++i) {
    methods.push_back(absl::StrCat("/", service->full_name(), "/", service->method(i)->name()));
  }
  return methods;
}

// Calls `method` with an empty request message (whatever its streaming kind: one message, then
// half-close) and returns the final status. `authorization` is sent as metadata when not null.
grpc::Status callRaw(const std::shared_ptr<grpc::Channel>& channel, const std::string& method,
                     const std::string* authorization) {
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  if (authorization) context.AddMetadata(auth::kAuthorizationKey, *authorization);
  grpc::Slice empty;
  grpc::ByteBuffer request(&empty, 1);
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  stub.UnaryCall(&context, method, grpc::StubOptions(), &request, &response,
                 [&done](grpc::Status status) { done.set_value(std::move(status)); });
  return done.get_future().get();
}

grpc::Status getStats(const std::shared_ptr<grpc::Channel>& channel, const std::string& token) {
  auto stub = v1::ObjectDatabase::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  if (!token.empty()) context.AddMetadata(auth::kAuthorizationKey, "Bearer " + token);
  v1::GetStatsResponse response;
  return stub->GetStats(&context, v1::GetStatsRequest(), &response);
}

grpc::Status checkHealth(const std::shared_ptr<grpc::Channel>& channel) {
  auto stub = grpc::health::v1::Health::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  grpc::health::v1::HealthCheckResponse response;
  return stub->Check(&context, grpc::health::v1::HealthCheckRequest(), &response);
}

std::shared_ptr<grpc::Channel> plaintextChannel(const std::string& address) {
  return grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
}

TEST(TokenAuth, EveryMethodRefusesAMissingOrWrongTokenAndAcceptsTheRightOne) {
  TempDir dir;
  ASSERT_TRUE(writeTextFile(dir / "token", std::string(kToken) + "\n"));
  ServerOptions options = loopbackOptions();
  options.token_file = (dir / "token").string();
  auto server = startOrDie(options);
  ASSERT_NE(server, nullptr);
  const auto channel = plaintextChannel(server->address());

  const std::vector<std::string> methods = serviceMethods();
  ASSERT_GE(methods.size(), 7u) << "the service descriptor lists the API's methods";
  const std::string right = std::string("Bearer ") + kToken;
  const std::string wrong = std::string("Bearer ") + kToken + "0";
  for (const std::string& method : methods) {
    for (const std::string* authorization : {static_cast<const std::string*>(nullptr), &wrong}) {
      const grpc::Status s = callRaw(channel, method, authorization);
      EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED)
          << method << (authorization ? " (wrong token)" : " (no token)") << ": "
          << s.error_message();
      EXPECT_FALSE(contains(s.error_message(), kToken)) << s.error_message();
    }
    // With the token the call reaches the method (an empty request is refused by it, or
    // answered), never with UNAUTHENTICATED.
    const grpc::Status s = callRaw(channel, method, &right);
    EXPECT_NE(s.error_code(), grpc::StatusCode::UNAUTHENTICATED) << method << ": "
                                                                 << s.error_message();
  }
  const grpc::Status stats = getStats(channel, kToken);
  EXPECT_TRUE(stats.ok()) << stats.error_message();
  const grpc::Status health = checkHealth(channel);
  EXPECT_TRUE(health.ok()) << "health needs no token: " << health.error_message();
}

TEST(TokenAuth, WithoutATokenFileEveryCallIsOpen) {
  auto server = startOrDie(loopbackOptions());
  ASSERT_NE(server, nullptr);
  const grpc::Status stats = getStats(plaintextChannel(server->address()), "");
  EXPECT_TRUE(stats.ok()) << stats.error_message();
}

std::shared_ptr<grpc::Channel> tlsChannel(const std::string& address, const std::string& ca_pem,
                                          const std::string& cert_pem = "",
                                          const std::string& key_pem = "") {
  grpc::SslCredentialsOptions o;
  o.pem_root_certs = ca_pem;
  o.pem_cert_chain = cert_pem;
  o.pem_private_key = key_pem;
  return grpc::CreateChannel(address, grpc::SslCredentials(o));
}

TEST(Tls, TlsWithATokenRefusesPlaintextOtherCasAndMissingTokens) {
  const TestPki pki;
  ASSERT_TRUE(pki.ok()) << pki.log();
  TempDir dir;
  ASSERT_TRUE(writeTextFile(dir / "token", kToken));
  ServerOptions options = loopbackOptions();
  options.token_file = (dir / "token").string();
  options.tls_cert_file = pki.path("server.pem");
  options.tls_key_file = pki.path("server.key");
  auto server = startOrDie(options);
  ASSERT_NE(server, nullptr);
  const std::string address = server->address();

  EXPECT_TRUE(getStats(tlsChannel(address, pki.read("ca.pem")), kToken).ok());
  EXPECT_EQ(getStats(tlsChannel(address, pki.read("ca.pem")), "").error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_EQ(getStats(plaintextChannel(address), kToken).error_code(),
            grpc::StatusCode::UNAVAILABLE)
      << "a plaintext client cannot talk to a TLS server";
  EXPECT_EQ(getStats(tlsChannel(address, pki.read("other_ca.pem")), kToken).error_code(),
            grpc::StatusCode::UNAVAILABLE)
      << "a client that trusts another CA refuses the server";
  EXPECT_TRUE(checkHealth(tlsChannel(address, pki.read("ca.pem"))).ok());
}

TEST(Tls, MutualTlsRefusesClientsWithoutACertificateOfTheClientCa) {
  const TestPki pki;
  ASSERT_TRUE(pki.ok()) << pki.log();
  ServerOptions options = loopbackOptions();
  options.tls_cert_file = pki.path("server.pem");
  options.tls_key_file = pki.path("server.key");
  options.tls_client_ca_file = pki.path("ca.pem");
  auto server = startOrDie(options);
  ASSERT_NE(server, nullptr);
  const std::string address = server->address();
  const std::string ca = pki.read("ca.pem");

  EXPECT_TRUE(
      getStats(tlsChannel(address, ca, pki.read("client.pem"), pki.read("client.key")), "").ok());
  EXPECT_EQ(getStats(tlsChannel(address, ca), "").error_code(), grpc::StatusCode::UNAVAILABLE)
      << "no client certificate";
  EXPECT_EQ(getStats(tlsChannel(address, ca, pki.read("other_client.pem"),
                                pki.read("other_client.key")),
                     "")
                .error_code(),
            grpc::StatusCode::UNAVAILABLE)
      << "a client certificate of another CA";
}

TEST(Tls, AKeyThatIsNotPemRefusesTheStart) {
  const TestPki pki;
  ASSERT_TRUE(pki.ok()) << pki.log();
  TempDir dir;
  ASSERT_TRUE(writeTextFile(dir / "bad.key", "not a key\n"));
  ServerOptions options = loopbackOptions();
  options.tls_cert_file = pki.path("server.pem");
  options.tls_key_file = (dir / "bad.key").string();
  const auto server = ObjdbServer::start(options);
  ASSERT_FALSE(server.ok());
  EXPECT_EQ(server.status().code(), absl::StatusCode::kUnavailable);
  EXPECT_TRUE(contains(std::string(server.status().message()), "TLS certificate and key"))
      << server.status();
}

}  // namespace
}  // namespace objdb
