// HOST:PORT addresses: parsing, and whether a host is reachable only from this machine. The
// server's listen policy and the client's rule for sending a token in clear text use it.
#pragma once

#include <string>

#include "core/common/status.h"

namespace objdb {

// A parsed HOST:PORT listen address.
struct ListenAddress {
  std::string host;       // as written, IPv6 with its brackets: "127.0.0.1", "localhost", "[::1]"
  int port = 0;           // 0..65535; 0 = let the system choose (ephemeral port)
  bool loopback = false;  // host is only reachable from this machine (127.0.0.0/8, ::1, localhost)
};

// Parses "HOST:PORT" where HOST is an IPv4 address, a bracketed IPv6 address or a DNS name.
// Host names other than "localhost" count as remote (they may resolve to any interface).
StatusOr<ListenAddress> parseListenAddress(const std::string& address);

// Whether this process could listen on `address` now: binds a socket to it (with SO_REUSEADDR,
// as gRPC does) and closes it again. UNAVAILABLE naming the address and the reason (port in use,
// not an address of this machine, not permitted, a host that does not resolve). Port 0 is always
// free. A probe, not a reservation: the server still checks its own bind.
Status probeListenAddress(const ListenAddress& address, const std::string& as_written);

}  // namespace objdb
