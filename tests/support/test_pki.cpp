#include "tests/support/test_pki.h"

#include <filesystem>
#include <fstream>
#include <iterator>
#include <vector>

#include "tests/support/subprocess.h"

namespace objdb::testing {
namespace {

constexpr char kOpenssl[] = "/usr/bin/openssl";

}  // namespace

TestPki::TestPki() {
  if (!std::filesystem::exists(kOpenssl)) {
    log_ = "openssl is not installed (scripts/deps.sh installs it)";
    return;
  }
  if (!writeTextFile(dir_ / "server.ext", "subjectAltName=DNS:localhost,IP:127.0.0.1\n") ||
      !writeTextFile(dir_ / "client.ext", "extendedKeyUsage=clientAuth\n")) {
    log_ = "cannot write the extension files";
    return;
  }
  auto run = [&](std::vector<std::string> args) {
    args.insert(args.begin(), kOpenssl);
    const ProcessResult r = runProcess(args);
    log_ += r.err;
    return r.exit_code == 0;
  };
  const std::vector<std::string> new_key = {"-newkey", "ec", "-pkeyopt",
                                            "ec_paramgen_curve:prime256v1", "-nodes"};
  auto request = [&](std::vector<std::string> head, const std::string& name,
                     const std::string& out_suffix, const std::string& subject) {
    head.insert(head.end(), new_key.begin(), new_key.end());
    for (const std::string& a : {std::string("-keyout"), path(name + ".key"), std::string("-out"),
                                 path(name + out_suffix), std::string("-subj"), subject}) {
      head.push_back(a);
    }
    return head;
  };
  auto ca = [&](const std::string& name) {
    std::vector<std::string> args = request({"req", "-x509"}, name, ".pem", "/CN=objdb test " + name);
    args.insert(args.end(), {"-days", "2"});
    return run(args);
  };
  auto leaf = [&](const std::string& name, const std::string& issuer, const std::string& cn,
                  const std::string& extensions) {
    return run(request({"req"}, name, ".csr", "/CN=" + cn)) &&
           run({"x509", "-req", "-in", path(name + ".csr"), "-CA", path(issuer + ".pem"),
                "-CAkey", path(issuer + ".key"), "-CAcreateserial", "-out", path(name + ".pem"),
                "-days", "2", "-extfile", path(extensions)});
  };
  ok_ = ca("ca") && ca("other_ca") && leaf("server", "ca", "localhost", "server.ext") &&
        leaf("client", "ca", "objdb client", "client.ext") &&
        leaf("other_client", "other_ca", "objdb other client", "client.ext");
}

std::string TestPki::read(const std::string& file) const {
  std::ifstream in(path(file));
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

}  // namespace objdb::testing
