// `objdb web`'s HTTP server (cpp-httplib): the pages (static files installed with the binary),
// three.js (Debian's libjs-three) and the API of web_api.h. Read-only: only GET and HEAD.
//
// Who may connect follows objdb-server's rule: a loopback address by default; any other address
// only with HTTPS (a certificate and its key) and a token, or with allow_remote. With a token,
// every request carries it as "Authorization: Bearer <token>" or as the cookie that
// GET /login?token=<token> sets (HttpOnly, SameSite=Strict; Secure under HTTPS) before it
// redirects to the sessions page; others get 401.
#pragma once

#include <map>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "core/common/status.h"

namespace objdb::web {

struct WebOptions {
  std::string listen = "127.0.0.1:8080";  // HOST:PORT; port 0 picks a free port
  std::string pages_dir;   // the static pages (index.html, ...)
  std::string three_dir = "/usr/share/javascript/three";  // libjs-three: build/, examples/js/
  std::string token_file;  // require this token (auth::readTokenFile's rules)
  std::string https_cert, https_key;  // serve HTTPS with this PEM chain and key
  bool allow_remote = false;
  // Session name → dataset folder: the object page then shows the model's merge-sheet row.
  std::map<std::string, std::string> datasets;
  double call_timeout_s = 30.0;    // deadline of each gRPC call
  double scene_timeout_s = 600.0;  // of GetSceneMesh (completion can take long)
};

class WebServer {
 public:
  // Checks the options (files readable, the address allowed) and binds the port. Errors:
  // INVALID_ARGUMENT (bad or refused address, missing pages, bad token or certificate files),
  // UNAVAILABLE (the port cannot be bound).
  static StatusOr<std::unique_ptr<WebServer>> start(std::shared_ptr<grpc::Channel> channel,
                                                    const WebOptions& options);
  ~WebServer();
  // "http://HOST:PORT" or "https://HOST:PORT", the port bound.
  const std::string& url() const;
  // Serves until stop() (from another thread or a signal handler's thread).
  void serve();
  void stop();

 private:
  WebServer();
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace objdb::web
