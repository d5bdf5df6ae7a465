#include "server/auth.h"

#include <grpcpp/security/credentials.h>
#include <grpcpp/security/server_credentials.h>

#include <fstream>
#include <iterator>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace objdb::auth {
namespace {

// PEM files and tokens are small; a CA bundle of a few hundred certificates stays below this.
constexpr std::streamoff kMaxCredentialFileBytes = 1 << 20;

// The whole file; `what` names its role in errors ("token file", "TLS certificate").
StatusOr<std::string> readSmallFile(const std::string& path, const char* what) {
  if (path.empty()) return absl::InvalidArgumentError(absl::StrCat(what, " path is empty"));
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) {
    return absl::NotFoundError(absl::StrCat(what, " ", path, " cannot be opened"));
  }
  const std::streamoff size = in.tellg();
  if (size < 0 || size > kMaxCredentialFileBytes) {
    return absl::InvalidArgumentError(absl::StrFormat("%s %s has %d bytes; at most %d expected",
                                                      what, path, int64_t(size),
                                                      int64_t(kMaxCredentialFileBytes)));
  }
  in.seekg(0);
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (!in.good() && !in.eof()) {
    return absl::DataLossError(absl::StrCat(what, " ", path, " could not be read"));
  }
  if (data.empty()) return absl::InvalidArgumentError(absl::StrCat(what, " ", path, " is empty"));
  return data;
}

}  // namespace

StatusOr<std::string> readTokenFile(const std::string& path) {
  OBJDB_ASSIGN_OR_RETURN(std::string data, readSmallFile(path, "token file"));
  const std::string token(absl::StripAsciiWhitespace(data));
  if (token.size() < kMinTokenChars || token.size() > kMaxTokenChars) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "token file %s holds %d characters; a token needs %d..%d (e.g. `openssl rand -hex 32 > %s`)",
        path, token.size(), kMinTokenChars, kMaxTokenChars, path));
  }
  for (unsigned char c : token) {
    if (c < 0x21 || c > 0x7e) {
      return absl::InvalidArgumentError(absl::StrCat(
          "token file ", path,
          " holds a space, control or non-ASCII character inside the token; a token is printable "
          "ASCII without spaces (it travels in a gRPC metadata value)"));
    }
  }
  return token;
}

bool constantTimeEquals(const std::string& a, const std::string& b) {
  // Every byte of the longer string is visited whatever the content; the lengths are not secret
  // (the token's length is fixed by its file).
  const size_t n = std::max(a.size(), b.size());
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (size_t i = 0; i < n; ++i) {
    const unsigned char x = i < a.size() ? static_cast<unsigned char>(a[i]) : 0;
    const unsigned char y = i < b.size() ? static_cast<unsigned char>(b[i]) : 0;
    diff |= static_cast<unsigned char>(x ^ y);
  }
  return diff == 0;
}

Status checkBearer(const std::string& token, const std::string* authorization) {
  if (token.empty()) return absl::OkStatus();
  if (authorization == nullptr) {
    return absl::UnauthenticatedError(
        "this server requires a token: send the metadata \"authorization: Bearer <token>\" "
        "(objdb clients: --token-file FILE)");
  }
  // The scheme is case-insensitive (RFC 7235), the token is not.
  const absl::string_view prefix = kBearerPrefix;
  if (authorization->size() < prefix.size() ||
      !absl::EqualsIgnoreCase(absl::string_view(*authorization).substr(0, prefix.size()), prefix) ||
      !constantTimeEquals(authorization->substr(prefix.size()), token)) {
    return absl::UnauthenticatedError("the bearer token of this call is not the server's token");
  }
  return absl::OkStatus();
}

Status checkTlsServerFiles(const TlsServerFiles& files) {
  if (files.cert_file.empty() != files.key_file.empty()) {
    return absl::InvalidArgumentError(
        "tls_cert_file and tls_key_file go together (--tls-cert with --tls-key)");
  }
  if (!files.client_ca_file.empty() && files.cert_file.empty()) {
    return absl::InvalidArgumentError(
        "tls_client_ca_file needs the server's own certificate (--tls-cert, --tls-key)");
  }
  return absl::OkStatus();
}

StatusOr<std::shared_ptr<grpc::ServerCredentials>> serverCredentials(const TlsServerFiles& files) {
  OBJDB_RETURN_IF_ERROR(checkTlsServerFiles(files));
  if (files.cert_file.empty()) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions options(
      files.client_ca_file.empty() ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
                                   : GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY);
  grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
  OBJDB_ASSIGN_OR_RETURN(pair.cert_chain, readSmallFile(files.cert_file, "TLS certificate"));
  OBJDB_ASSIGN_OR_RETURN(pair.private_key, readSmallFile(files.key_file, "TLS key"));
  options.pem_key_cert_pairs.push_back(std::move(pair));
  if (!files.client_ca_file.empty()) {
    OBJDB_ASSIGN_OR_RETURN(options.pem_root_certs,
                           readSmallFile(files.client_ca_file, "TLS client CA"));
  }
  return grpc::SslServerCredentials(options);
}

StatusOr<std::shared_ptr<grpc::ChannelCredentials>> channelCredentials(const TlsClientFiles& files) {
  if (files.ca_file.empty()) {
    if (!files.cert_file.empty() || !files.key_file.empty()) {
      return absl::InvalidArgumentError(
          "a client certificate or key was given without the server's CA (--tls-ca)");
    }
    return grpc::InsecureChannelCredentials();
  }
  if (files.cert_file.empty() != files.key_file.empty()) {
    return absl::InvalidArgumentError(
        "a client certificate needs its key and a key its certificate (--tls-cert with --tls-key)");
  }
  grpc::SslCredentialsOptions options;
  OBJDB_ASSIGN_OR_RETURN(options.pem_root_certs, readSmallFile(files.ca_file, "TLS CA"));
  if (!files.cert_file.empty()) {
    OBJDB_ASSIGN_OR_RETURN(options.pem_cert_chain,
                           readSmallFile(files.cert_file, "TLS client certificate"));
    OBJDB_ASSIGN_OR_RETURN(options.pem_private_key, readSmallFile(files.key_file, "TLS client key"));
  }
  return grpc::SslCredentials(options);
}

}  // namespace objdb::auth
