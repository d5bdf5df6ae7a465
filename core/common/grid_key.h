// 64-bit keys of integer grid cells (voxels, buckets): 21 bits per axis, cells in
// [−2^20, 2^20) — ±10 km at 1 cm — map one-to-one.
#pragma once

#include <cstdint>

#include <Eigen/Core>

namespace objdb {

inline uint64_t packGridKey(const Eigen::Vector3i& c) {
  auto f = [](int x) { return uint64_t(uint32_t(x + (1 << 20)) & 0x1fffffu); };
  return f(c.x()) | (f(c.y()) << 21) | (f(c.z()) << 42);
}

inline Eigen::Vector3i unpackGridKey(uint64_t key) {
  auto g = [](uint64_t bits) { return int(bits & 0x1fffffu) - (1 << 20); };
  return {g(key), g(key >> 21), g(key >> 42)};
}

}  // namespace objdb
