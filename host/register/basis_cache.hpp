#pragma once
// A cache of load bases on disk (arnav-register --basis-cache DIR, docs/register.md). The
// basis depends only on the scene (the volume's rest positions, tets, regions, surface
// triangles, per-region materials, fixed vertices) and the basis options, so it is built
// once (0.1-0.3 s idle, more on a loaded machine) and loaded on later runs. The file is
// named by a 128-bit hash of all of these (load_basis_key), written atomically (temp file
// then rename); a file that is corrupt, truncated, stale (other key, other sizes) or holds
// NaN is never used: a warning names it and the basis is rebuilt. The cache never makes a
// registration fail: a folder that cannot be written only warns.
#include <memory>
#include <string>
#include <vector>

#include "host/register/load_basis.hpp"
#include "host/scene/scene.hpp"

namespace arnav::host {

// Bump when build_load_basis changes what it computes: older files are then never matched.
inline constexpr const char* kLoadBasisAlgorithm = "arnav load basis v1";

// 32 hex digits: a hash of everything build_load_basis reads (not cryptographic: the cache
// folder is trusted as the scene files are; the file is still checked in full).
std::string load_basis_key(const Scene& scene, const LoadBasisOptions& options);

struct CachedBasis {
  std::shared_ptr<const LoadBasis> basis;
  std::string source;                 // "built" or "loaded"
  double time_s = 0.0;                // build or load (read + check) time
  std::string path;                   // the cache file (read or written)
  std::vector<std::string> warnings;  // cache problems (a file rebuilt, a folder not writable)
};

// The basis from DIR/load_basis_<key>.bin when that file is valid, else built (and written
// there). Throws std::invalid_argument only when the basis cannot be built (as build_load_basis).
CachedBasis cached_load_basis(const Scene& scene, const LoadBasisOptions& options, const std::string& dir);

}  // namespace arnav::host
