#include "host/register/basis_cache.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <system_error>
#include <unistd.h>

#include "host/register/basis_cache_file.hpp"
#include "host/mesh/load_error.hpp"

namespace arnav::host {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// Two independent 64-bit lanes (FNV-1a and a multiply-xorshift mix) over the same bytes.
class Hasher {
 public:
  void bytes(const void* p, std::size_t n) {
    const auto* c = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) {
      a_ = (a_ ^ c[i]) * 0x100000001b3ULL;
      b_ = (b_ + c[i] + 1) * 0x9e3779b97f4a7c15ULL;
      b_ ^= b_ >> 29;
    }
  }
  template <class T>
  void pod(const T& v) {
    bytes(&v, sizeof v);
  }
  void text(const std::string& s) {
    pod(static_cast<std::uint64_t>(s.size()));
    bytes(s.data(), s.size());
  }
  template <class T>
  void vec(const std::vector<T>& v) {
    pod(static_cast<std::uint64_t>(v.size()));
    if (!v.empty()) bytes(v.data(), v.size() * sizeof(T));
  }
  std::string hex() const {
    char buf[33];
    std::snprintf(buf, sizeof buf, "%016llx%016llx", static_cast<unsigned long long>(a_), static_cast<unsigned long long>(b_));
    return buf;
  }

 private:
  std::uint64_t a_ = 0xcbf29ce484222325ULL, b_ = 0x243f6a8885a308d3ULL;
};

std::string read_all(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  if (!f && !f.eof()) throw LoadError(path + ": cannot be read");
  return s.str();
}

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

}  // namespace

std::string load_basis_key(const Scene& scene, const LoadBasisOptions& o) {
  const TetMesh& mesh = scene.problem.mesh;
  Hasher h;
  h.text(kLoadBasisAlgorithm);
  h.pod(static_cast<std::int64_t>(mesh.rest_positions_World_mm.cols()));
  h.bytes(mesh.rest_positions_World_mm.data(), sizeof(double) * static_cast<std::size_t>(mesh.rest_positions_World_mm.size()));
  h.vec(mesh.tets);
  h.vec(mesh.tet_region);
  h.vec(mesh.surface_tris);
  h.pod(static_cast<std::uint64_t>(scene.problem.region_materials.size()));
  for (const Material& m : scene.problem.region_materials) {
    h.pod(m.youngs_modulus_kPa);
    h.pod(m.poisson_ratio);
    h.pod(m.density_kg_per_mm3);
  }
  // the basis sees the fixed vertices as a set
  std::vector<int> fixed = scene.problem.fixed_vertices;
  std::sort(fixed.begin(), fixed.end());
  fixed.erase(std::unique(fixed.begin(), fixed.end()), fixed.end());
  h.vec(fixed);
  h.pod(static_cast<std::int32_t>(o.patches));
  h.pod(static_cast<std::int32_t>(o.gravity_modes ? 1 : 0));
  h.pod(static_cast<std::int32_t>(o.support_clusters));
  return h.hex();
}

CachedBasis cached_load_basis(const Scene& scene, const LoadBasisOptions& options, const std::string& dir) {
  CachedBasis c;
  const auto t0 = Clock::now();
  const std::string key = load_basis_key(scene, options);
  const std::string name = "load_basis_" + key + ".bin";
  c.path = (fs::path(dir) / name).string();
  const int dofs = 3 * scene.problem.mesh.num_vertices();
  std::error_code ec;
  if (fs::is_regular_file(c.path, ec)) {
    try {
      c.basis = std::make_shared<const LoadBasis>(parse_load_basis(read_all(c.path), key, dofs, c.path));
      c.source = "loaded";
      c.time_s = seconds_since(t0);
      return c;
    } catch (const LoadError& e) {
      c.warnings.push_back(std::string("basis cache: ") + e.what());
    }
  }
  auto built = std::make_shared<LoadBasis>(build_load_basis(scene, options));
  c.basis = built;
  c.source = "built";
  c.time_s = built->build_time_s;
  // Write atomically: a temp file in the same folder, renamed over the final name, so a
  // concurrent reader sees the old file, no file, or the whole new one.
  fs::create_directories(dir, ec);
  if (ec) {
    c.warnings.push_back("basis cache: cannot create the folder " + dir + " (" + ec.message() + "); the basis is not cached. Fix: give a writable --basis-cache folder");
    return c;
  }
  // unique per process and call: concurrent writers never share a temp file
  static std::atomic<unsigned> calls{0};
  const std::string tmp = (fs::path(dir) / ("." + name + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(calls++) + "-" +
                                            std::to_string(Clock::now().time_since_epoch().count())))
                              .string();
  bool ok = false;
  {
    std::ofstream f(tmp, std::ios::binary | std::ios::trunc);
    if (f) {
      const std::string bytes = serialize_load_basis(*built, key);
      f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
      f.close();
      ok = static_cast<bool>(f);
    }
  }
  if (ok) {
    fs::rename(tmp, c.path, ec);
    ok = !ec;
  }
  if (!ok) {
    fs::remove(tmp, ec);
    c.warnings.push_back("basis cache: cannot write " + c.path + " (folder not writable or disk full); the basis is not cached. Fix: give a writable --basis-cache folder");
  }
  return c;
}

}  // namespace arnav::host
