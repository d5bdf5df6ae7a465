#include "server/address.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <sys/socket.h>
#include <unistd.h>
#include <netinet/in.h>

#include <algorithm>
#include <cctype>

#include <cerrno>
#include <cstring>

#include "absl/strings/str_cat.h"

namespace objdb {
namespace {

bool isDigits(const std::string& text) {
  return !text.empty() &&
         std::all_of(text.begin(), text.end(), [](unsigned char c) { return std::isdigit(c); });
}

// RFC 1123 host name: dot-separated labels of letters, digits and '-', 1..63 characters each,
// not starting or ending with '-'; at most 253 characters.
bool isHostName(const std::string& host) {
  if (host.empty() || host.size() > 253) return false;
  size_t start = 0;
  while (start <= host.size()) {
    size_t end = host.find('.', start);
    if (end == std::string::npos) end = host.size();
    const std::string label = host.substr(start, end - start);
    if (label.empty() || label.size() > 63 || label.front() == '-' || label.back() == '-') {
      return false;
    }
    for (unsigned char c : label) {
      if (!std::isalnum(c) && c != '-') return false;
    }
    start = end + 1;
  }
  return true;
}

}  // namespace

StatusOr<ListenAddress> parseListenAddress(const std::string& address) {
  auto bad = [&address](absl::string_view why) {
    return absl::InvalidArgumentError(absl::StrCat("listen address \"", address, "\" ", why,
                                                   " (expected HOST:PORT, e.g. 127.0.0.1:50051)"));
  };
  if (address.empty()) return bad("is empty");
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos) return bad("has no port");

  ListenAddress result;
  result.host = address.substr(0, colon);
  const std::string port_text = address.substr(colon + 1);
  if (!isDigits(port_text) || port_text.size() > 5) return bad("has no valid port number");
  result.port = std::stoi(port_text);
  if (result.port > 65535) return bad("has a port above 65535");
  if (result.host.empty()) return bad("has no host");

  if (result.host.front() == '[') {
    if (result.host.size() < 3 || result.host.back() != ']') return bad("has an unclosed '['");
    const std::string inner = result.host.substr(1, result.host.size() - 2);
    in6_addr ip6{};
    if (inet_pton(AF_INET6, inner.c_str(), &ip6) != 1) return bad("has an invalid IPv6 address");
    result.loopback =
        IN6_IS_ADDR_LOOPBACK(&ip6) || (IN6_IS_ADDR_V4MAPPED(&ip6) && ip6.s6_addr[12] == 127);
  } else if (result.host.find(':') != std::string::npos) {
    return bad("has an IPv6 address without brackets (write [::1]:PORT)");
  } else if (std::all_of(result.host.begin(), result.host.end(),
                         [](unsigned char c) { return std::isdigit(c) || c == '.'; })) {
    in_addr ip4{};
    if (inet_pton(AF_INET, result.host.c_str(), &ip4) != 1) {
      return bad("has an invalid IPv4 address");
    }
    result.loopback = (ntohl(ip4.s_addr) >> 24) == 127;
  } else {
    if (!isHostName(result.host)) return bad("has an invalid host name");
    std::string lower = result.host;
    std::transform(lower.begin(), lower.end(), lower.begin(),
                   [](unsigned char c) { return std::tolower(c); });
    result.loopback = lower == "localhost";
  }
  return result;
}

Status probeListenAddress(const ListenAddress& address, const std::string& as_written) {
  if (address.port == 0) return absl::OkStatus();
  std::string host = address.host;
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') {
    host = host.substr(1, host.size() - 2);
  }
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* found = nullptr;
  const std::string port = std::to_string(address.port);
  if (getaddrinfo(host.c_str(), port.c_str(), &hints, &found) != 0 || found == nullptr) {
    return absl::UnavailableError(
        absl::StrCat("cannot listen on ", as_written, ": the host does not resolve"));
  }
  int error = 0;
  for (const addrinfo* a = found; a != nullptr && error == 0; a = a->ai_next) {
    const int fd = socket(a->ai_family, a->ai_socktype, a->ai_protocol);
    if (fd < 0) continue;  // a family this machine lacks (IPv6): gRPC skips it too
    const int one = 1;
    (void)setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
    if (bind(fd, a->ai_addr, a->ai_addrlen) != 0) error = errno;
    close(fd);
  }
  freeaddrinfo(found);
  if (error == 0) return absl::OkStatus();
  const char* why = error == EADDRINUSE      ? "the port is in use (another objdb-server?)"
                    : error == EADDRNOTAVAIL ? "the host is not an address of this machine"
                    : error == EACCES        ? "binding it is not permitted (ports below 1024 "
                                               "need privileges)"
                                             : std::strerror(error);
  return absl::UnavailableError(absl::StrCat("cannot listen on ", as_written, ": ", why));
}

}  // namespace objdb
