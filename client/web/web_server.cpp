// The one file that includes cpp-httplib (Debian's build: HTTPS through OpenSSL; its
// CPPHTTPLIB_* definitions come from pkg-config, so that they match the library's).
#include "client/web/web_server.h"

#include <httplib.h>

#include <filesystem>
#include <fstream>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "client/web/web_api.h"
#include "core/common/logging.h"
#include "server/address.h"
#include "server/auth.h"

namespace objdb::web {
namespace fs = std::filesystem;

namespace {

constexpr const char* kCookie = "objdb_web";

void send(const Reply& reply, httplib::Response& res) {
  res.status = reply.status;
  res.set_content(reply.body, reply.content_type.c_str());
  res.set_header("Cache-Control", "no-store");
}

// The token of a request: its bearer header, else its cookie (empty when neither).
std::string requestToken(const httplib::Request& req) {
  const std::string authorization = req.get_header_value("Authorization");
  if (absl::StartsWithIgnoreCase(authorization, "Bearer ")) {
    return std::string(absl::StripAsciiWhitespace(authorization.substr(7)));
  }
  for (absl::string_view part : absl::StrSplit(req.get_header_value("Cookie"), ';')) {
    part = absl::StripAsciiWhitespace(part);
    if (absl::ConsumePrefix(&part, kCookie) && absl::ConsumePrefix(&part, "=")) {
      return std::string(part);
    }
  }
  return "";
}

bool readable(const std::string& path) { return std::ifstream(path).good(); }

}  // namespace

struct WebServer::Impl {
  std::unique_ptr<httplib::Server> http;
  std::unique_ptr<WebApi> api;
  std::string token;
  std::string url;
  bool https = false;
};

WebServer::WebServer() : impl_(std::make_unique<Impl>()) {}
WebServer::~WebServer() = default;

const std::string& WebServer::url() const { return impl_->url; }

void WebServer::serve() { impl_->http->listen_after_bind(); }

void WebServer::stop() { impl_->http->stop(); }

StatusOr<std::unique_ptr<WebServer>> WebServer::start(std::shared_ptr<grpc::Channel> channel,
                                                      const WebOptions& options) {
  OBJDB_ASSIGN_OR_RETURN(const ListenAddress address, parseListenAddress(options.listen));
  const bool https = !options.https_cert.empty() || !options.https_key.empty();
  if (https && (options.https_cert.empty() || options.https_key.empty())) {
    return absl::InvalidArgumentError("HTTPS needs both --https-cert and --https-key");
  }
  if (!address.loopback && !options.allow_remote && !(https && !options.token_file.empty())) {
    return absl::InvalidArgumentError(absl::StrCat(
        "refusing to serve on ", options.listen,
        ", which is reachable from other machines, without HTTPS and a token: give "
        "--https-cert, --https-key and --token-file, listen on 127.0.0.1, or accept the risk "
        "with --allow-remote"));
  }
  if (!fs::is_regular_file(fs::path(options.pages_dir) / "index.html")) {
    return absl::InvalidArgumentError(absl::StrCat(
        "no web pages in '", options.pages_dir, "' (index.html missing; --pages DIR)"));
  }
  if (!fs::is_regular_file(fs::path(options.three_dir) / "build" / "three.min.js")) {
    return absl::InvalidArgumentError(
        absl::StrCat("no three.js in '", options.three_dir,
                     "' (build/three.min.js missing: install Debian's libjs-three, or --three DIR)"));
  }
  auto server = std::unique_ptr<WebServer>(new WebServer());
  Impl& impl = *server->impl_;
  if (!options.token_file.empty()) {
    OBJDB_ASSIGN_OR_RETURN(impl.token, auth::readTokenFile(options.token_file));
  }
  if (https) {
    for (const std::string& file : {options.https_cert, options.https_key}) {
      if (!readable(file)) return absl::InvalidArgumentError("cannot read " + file);
    }
    auto ssl = std::make_unique<httplib::SSLServer>(options.https_cert.c_str(),
                                                    options.https_key.c_str());
    if (!ssl->is_valid()) {
      return absl::InvalidArgumentError(absl::StrCat(
          "the HTTPS certificate ", options.https_cert, " or its key ", options.https_key,
          " is not usable (PEM, matching pair)"));
    }
    impl.http = std::move(ssl);
  } else {
    impl.http = std::make_unique<httplib::Server>();
  }
  impl.https = https;
  for (const auto& [session, folder] : options.datasets) {
    if (!fs::is_directory(folder)) {
      return absl::InvalidArgumentError(
          absl::StrCat("--dataset ", session, "=", folder, ": no such folder"));
    }
  }
  impl.api = std::make_unique<WebApi>(std::move(channel), options.call_timeout_s,
                                      options.scene_timeout_s, options.datasets);
  httplib::Server& http = *impl.http;
  WebApi& api = *impl.api;

  // Read-only: nothing but GET (and HEAD) is routed.
  http.set_pre_routing_handler([&impl](const httplib::Request& req, httplib::Response& res) {
    if (impl.token.empty() || req.path == "/login") return httplib::Server::HandlerResponse::Unhandled;
    if (auth::constantTimeEquals(requestToken(req), impl.token)) {
      return httplib::Server::HandlerResponse::Unhandled;
    }
    send(WebApi::error(401, "this objdb web needs its token: open /login?token=... once, or send "
                            "\"Authorization: Bearer <token>\""),
         res);
    return httplib::Server::HandlerResponse::Handled;
  });
  http.Get("/login", [&impl](const httplib::Request& req, httplib::Response& res) {
    const std::string token = req.get_param_value("token");
    if (impl.token.empty() || !auth::constantTimeEquals(token, impl.token)) {
      send(WebApi::error(impl.token.empty() ? 404 : 401,
                         impl.token.empty() ? "this objdb web needs no token" : "wrong token"),
           res);
      return;
    }
    res.set_header("Set-Cookie", absl::StrCat(kCookie, "=", token,
                                              "; Path=/; HttpOnly; SameSite=Strict",
                                              impl.https ? "; Secure" : ""));
    res.set_redirect("/", 303);
  });
  http.Get("/api/sessions", [&api](const httplib::Request& req, httplib::Response& res) {
    send(api.sessions(req.params), res);
  });
  http.Get("/api/objects", [&api](const httplib::Request& req, httplib::Response& res) {
    send(api.objects(req.params), res);
  });
  http.Get(R"(/api/objects/([^/]+))", [&api](const httplib::Request& req,
                                              httplib::Response& res) {
    send(api.object(req.matches[1], req.params), res);
  });
  http.Get(R"(/api/objects/([^/]+)/(mesh|cloud)\.ply)",
           [&api](const httplib::Request& req, httplib::Response& res) {
             send(api.objectGeometry(req.matches[1], req.matches[2], req.params), res);
           });
  http.Get(R"(/api/objects/([^/]+)/thumbnail/([^/]+)\.png)",
           [&api](const httplib::Request& req, httplib::Response& res) {
             send(api.thumbnail(req.matches[1], req.matches[2], req.params), res);
           });
  http.Get(R"(/api/objects/([^/]+)/sheet\.png)",
           [&api](const httplib::Request& req, httplib::Response& res) {
             send(api.sheet(req.matches[1], req.params), res);
           });
  http.Get(R"(/api/objects/([^/]+)/similar)",
           [&api](const httplib::Request& req, httplib::Response& res) {
             send(api.similar(req.matches[1], req.params), res);
           });
  http.Get("/api/viewer", [&api](const httplib::Request& req, httplib::Response& res) {
    send(api.viewer(req.params), res);
  });
  http.Get(R"(/api/sessions/([^/]+)/scene\.ply)",
           [&api](const httplib::Request& req, httplib::Response& res) {
             send(api.scene(req.matches[1], req.params), res);
           });
  http.Get("/api/stats", [&api](const httplib::Request& req, httplib::Response& res) {
    send(api.stats(req.params), res);
  });
  http.Get(R"(/api(/.*)?)", [](const httplib::Request& req, httplib::Response& res) {
    send(WebApi::error(404, "no such endpoint: " + req.path), res);
  });
  if (!http.set_mount_point("/three", options.three_dir) ||
      !http.set_mount_point("/", options.pages_dir)) {
    return absl::InvalidArgumentError("cannot serve the pages or three.js folders");
  }
  // A JavaScript type that cpp-httplib does not compress: it would brotli three.min.js (850 kB)
  // at its highest quality on every request, about a second each time.
  http.set_file_extension_and_mimetype_mapping("js", "application/x-javascript");
  http.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
    if (res.status == 404 && res.body.empty()) {
      send(WebApi::error(404, "not found: " + req.path), res);
    }
  });

  std::string host = address.host;
  if (host.size() > 2 && host.front() == '[') host = host.substr(1, host.size() - 2);
  int port = address.port;
  if (port == 0) {
    port = http.bind_to_any_port(host);
    if (port < 0) return absl::UnavailableError("cannot bind " + options.listen);
  } else if (!http.bind_to_port(host, port)) {
    return absl::UnavailableError(absl::StrCat("cannot bind ", options.listen,
                                               " (in use, or not an address of this machine)"));
  }
  impl.url = absl::StrCat(https ? "https://" : "http://", address.host, ":", port);
  return server;
}

}  // namespace objdb::web
