#pragma once
// The load basis cache's file (arnav-register --basis-cache, docs/register.md): one binary
// file per basis, little-endian:
//   8 bytes   magic "ARNAVLB1"
//   8 bytes   uint64 length H of the header
//   H bytes   JSON header: format, version, key (the hash of everything the basis depends
//             on, basis_cache.hpp), dofs, modes, patches, gravity, support, supported,
//             stiffness_volume, build_time_s, mode_kind, payload_bytes, payload_checksum
//   payload   U (dofs x modes doubles, column-major), G (modes x modes doubles),
//             patch_of_vertex (dofs / 3 int32)
// The reader trusts nothing: every size, the checksum, the key, finiteness and the mode
// bookkeeping are checked before the basis is used.
#include <cstdint>
#include <string>
#include <string_view>

#include "host/register/load_basis_types.hpp"

namespace arnav::host {

inline constexpr int kBasisCacheVersion = 1;

// The file's bytes for basis b under key.
std::string serialize_load_basis(const LoadBasis& b, const std::string& key);

// Parses a cache file's bytes. expected_key / expected_dofs: the scene's (empty / <= 0:
// not checked, e.g. for the fuzzer). Throws LoadError naming `name` and what is wrong.
LoadBasis parse_load_basis(std::string_view bytes, const std::string& expected_key, int expected_dofs, const std::string& name);

// 64-bit FNV-1a of bytes (the payload checksum; not cryptographic).
std::uint64_t fnv1a64(std::string_view bytes, std::uint64_t h = 0xcbf29ce484222325ULL);

}  // namespace arnav::host
