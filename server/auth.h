// Who may call the server (docs/server.md): an optional bearer token and optional TLS
// (server certificate; with a client CA, mutual TLS). Shared by the server (credentials, the
// token check every objdb.v1.ObjectDatabase handler runs first) and the client (channel
// credentials, the token attached to every call).
//
// - Token: the file's content, surrounding whitespace removed, at least kMinTokenChars and at
//   most kMaxTokenChars printable ASCII characters. A call carries it as the metadata
//   "authorization: Bearer <token>" (the scheme in any case). Clients send it in clear text only
//   to a loopback address. It is read from a file (never argv, where `ps` shows it),
//   compared in constant time and never logged or echoed in an error.
// - TLS: PEM certificate chain + private key for the server; PEM CA bundle on the client. With
//   a client CA on the server, a client must present a certificate that CA signed (mTLS).
#pragma once

#include <map>
#include <memory>
#include <string>

#include "core/common/status.h"

namespace grpc {
class ServerCredentials;
class ChannelCredentials;
}  // namespace grpc

namespace objdb::auth {

inline constexpr size_t kMinTokenChars = 16;
inline constexpr size_t kMaxTokenChars = 4096;
inline constexpr char kAuthorizationKey[] = "authorization";
inline constexpr char kBearerPrefix[] = "Bearer ";

// Reads a token file (see above). Errors name the file and the rule broken, never the content.
StatusOr<std::string> readTokenFile(const std::string& path);

// True when `a` equals `b`; the time taken depends on the lengths only, not on where they differ.
bool constantTimeEquals(const std::string& a, const std::string& b);

// OK when `authorization` (the call's metadata value, or null when absent) is "Bearer <token>";
// UNAUTHENTICATED otherwise, with a message that names what is missing but quotes nothing of
// what was sent. An empty `token` means the server has no token: every call is OK.
Status checkBearer(const std::string& token, const std::string* authorization);

struct TlsServerFiles {
  std::string cert_file;       // PEM certificate chain; empty = plaintext
  std::string key_file;        // PEM private key of that certificate
  std::string client_ca_file;  // PEM CA bundle: clients must present a certificate it signed
};

// Which files go together (certificate with key; a client CA only with both), without reading
// them: the server's option check and serverCredentials both use it.
Status checkTlsServerFiles(const TlsServerFiles& files);

// Plaintext (no cert file) or TLS / mTLS server credentials from the PEM files. Errors name an
// unreadable or empty file; gRPC itself rejects a key that does not match the certificate when
// the listener starts.
StatusOr<std::shared_ptr<grpc::ServerCredentials>> serverCredentials(const TlsServerFiles& files);

struct TlsClientFiles {
  std::string ca_file;    // PEM CA bundle that signed the server's certificate; empty = plaintext
  std::string cert_file;  // PEM client certificate (mTLS), with key_file
  std::string key_file;
};

StatusOr<std::shared_ptr<grpc::ChannelCredentials>> channelCredentials(const TlsClientFiles& files);

}  // namespace objdb::auth
