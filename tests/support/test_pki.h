// A throwaway public-key infrastructure for TLS tests, made with the openssl command-line tool
// (installed by scripts/deps.sh) in a temporary folder: a CA ("ca"), a server certificate it
// signed for localhost / 127.0.0.1 ("server"), a client certificate it signed ("client"), and a
// second CA with a client certificate of its own ("other_ca", "other_client"). Each name has
// NAME.pem (certificate) and NAME.key (private key). EC P-256 keys, valid for two days.
#pragma once

#include <string>

#include "tests/support/temp_dir.h"

namespace objdb::testing {

class TestPki {
 public:
  TestPki();
  // False when a certificate could not be made; log() then says why.
  bool ok() const { return ok_; }
  const std::string& log() const { return log_; }
  std::string path(const std::string& file) const { return (dir_ / file).string(); }
  // The content of a file of the PKI ("ca.pem", "client.key", ...).
  std::string read(const std::string& file) const;

 private:
  TempDir dir_;
  bool ok_ = false;
  std::string log_;
};

}  // namespace objdb::testing
