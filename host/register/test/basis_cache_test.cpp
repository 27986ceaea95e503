// The load basis cache (basis_cache.hpp, basis_cache_file.hpp):
//  - a file written by one run is loaded by the next and gives the identical basis (and so
//    identical registrations: fit_load_basis on both is compared);
//  - the key changes with every input the basis depends on (a material's E, nu, density,
//    the fixed set, the rest positions, the basis options) and not with the fixed
//    vertices' order; a changed material or fixed set builds a new file;
//  - a truncated, corrupt, stale (other key, other size) or NaN file is never used: it is
//    rebuilt with a warning naming it; a folder that cannot be written warns and the basis
//    is still returned.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <unistd.h>

#include "host/register/basis_cache.hpp"
#include "host/register/basis_cache_file.hpp"
#include "host/mesh/box_mesh.hpp"
#include "host/mesh/load_error.hpp"

using namespace arnav::host;
namespace fs = std::filesystem;

namespace {

Scene bar() {
  Scene s;
  s.problem.mesh = make_box_tet_mesh(8, 2, 2, Eigen::Vector3d(80, 20, 20));
  s.problem.mesh.tet_region.assign(s.problem.mesh.tets.size(), 0);
  s.problem.mesh.region_names = {"default"};
  s.problem.region_materials = {Material{.youngs_modulus_kPa = 5.0, .poisson_ratio = 0.3}};
  for (int v = 0; v < s.problem.mesh.num_vertices(); ++v)
    if (s.problem.mesh.rest_positions_World_mm(0, v) < 1e-9) s.problem.fixed_vertices.push_back(v);
  s.organ_surface.positions_World_mm = s.problem.mesh.rest_positions_World_mm;
  s.organ_surface.tris = s.problem.mesh.surface_tris;
  return s;
}

LoadBasisOptions opts() {
  LoadBasisOptions o;
  o.patches = 8;
  o.support_clusters = 2;
  return o;
}

fs::path fresh_dir(const std::string& name) {
  const fs::path d = fs::path(testing::TempDir()) / ("arnav_basis_cache_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  return d;
}

std::string read(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

void write(const fs::path& p, const std::string& bytes) {
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// exact: a basis and its file; rebuilt: two builds (the factorisation may sum in another order)
void expect_same(const LoadBasis& a, const LoadBasis& b, bool exact = true) {
  if (exact) {
    EXPECT_EQ(a.U, b.U);
    EXPECT_EQ(a.G, b.G);
    EXPECT_EQ(a.stiffness_volume, b.stiffness_volume);
  } else {
    EXPECT_LE((a.U - b.U).cwiseAbs().maxCoeff(), 1e-12);
    EXPECT_LE((a.G - b.G).cwiseAbs().maxCoeff(), 1e-12 * a.G.cwiseAbs().maxCoeff());
    EXPECT_NEAR(a.stiffness_volume, b.stiffness_volume, 1e-12 * a.stiffness_volume);
  }
  EXPECT_EQ(a.mode_kind, b.mode_kind);
  EXPECT_EQ(a.patch_of_vertex, b.patch_of_vertex);
  EXPECT_EQ(a.patches, b.patches);
  EXPECT_EQ(a.gravity, b.gravity);
  EXPECT_EQ(a.support, b.support);
  EXPECT_EQ(a.supported, b.supported);
  EXPECT_EQ(a.dofs, b.dofs);
}

bool any_warning_names(const CachedBasis& c, const std::string& what) {
  for (const auto& w : c.warnings)
    if (w.find(c.path) != std::string::npos && w.find(what) != std::string::npos) return true;
  return false;
}

}  // namespace

TEST(BasisCache, SecondRunLoadsTheIdenticalBasis) {
  const Scene s = bar();
  const fs::path dir = fresh_dir("reuse");
  const CachedBasis first = cached_load_basis(s, opts(), dir.string());
  EXPECT_EQ(first.source, "built");
  EXPECT_TRUE(first.warnings.empty());
  ASSERT_TRUE(fs::exists(first.path));
  // no temp file left behind
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir)) files += e.is_regular_file() ? 1 : 0;
  EXPECT_EQ(files, 1);
  const CachedBasis second = cached_load_basis(s, opts(), dir.string());
  EXPECT_EQ(second.source, "loaded");
  EXPECT_TRUE(second.warnings.empty());
  EXPECT_EQ(second.path, first.path);
  expect_same(*first.basis, *second.basis);
  // the same registration from both: the surface vertices, deformed by two of the modes
  const Eigen::VectorXd a0 = Eigen::VectorXd::Unit(first.basis->modes(), 0) * 3.0 - Eigen::VectorXd::Unit(first.basis->modes(), 4) * 2.0;
  const Eigen::VectorXd u = first.basis->U * a0;
  std::vector<char> on_surface(static_cast<std::size_t>(s.problem.mesh.num_vertices()), 0);
  for (const auto& f : s.problem.mesh.surface_tris)
    for (int v : f) on_surface[static_cast<std::size_t>(v)] = 1;
  std::vector<Eigen::Vector3d> pts;
  for (int v = 0; v < s.problem.mesh.num_vertices(); ++v)
    if (on_surface[static_cast<std::size_t>(v)]) pts.push_back(s.problem.mesh.rest_positions_World_mm.col(v) + u.segment<3>(3 * v));
  Eigen::Matrix3Xd data(3, static_cast<Eigen::Index>(pts.size()));
  for (std::size_t i = 0; i < pts.size(); ++i) data.col(static_cast<Eigen::Index>(i)) = pts[i];
  LoadFitOptions fo;
  fo.noise_mm = 0.05;
  const LoadFitResult a = fit_load_basis(s, *first.basis, data, fo);
  const LoadFitResult b = fit_load_basis(s, *second.basis, data, fo);
  EXPECT_TRUE(a.accepted);
  EXPECT_EQ(a.x_Model_mm, b.x_Model_mm);
  EXPECT_EQ(a.alpha, b.alpha);
  // and the same basis as a fresh build
  expect_same(*first.basis, build_load_basis(s, opts()), false);
  fs::remove_all(dir);
}

TEST(BasisCache, KeyFollowsEveryInputOfTheBasis) {
  const Scene s = bar();
  const std::string k0 = load_basis_key(s, opts());
  EXPECT_EQ(k0.size(), 32u);
  EXPECT_EQ(load_basis_key(s, opts()), k0);
  auto changed = [&](auto edit) {
    Scene t = s;
    LoadBasisOptions o = opts();
    edit(t, o);
    return load_basis_key(t, o);
  };
  EXPECT_NE(changed([](Scene& t, LoadBasisOptions&) { t.problem.region_materials[0].youngs_modulus_kPa = 6.0; }), k0);
  EXPECT_NE(changed([](Scene& t, LoadBasisOptions&) { t.problem.region_materials[0].poisson_ratio = 0.31; }), k0);
  EXPECT_NE(changed([](Scene& t, LoadBasisOptions&) { t.problem.region_materials[0].density_kg_per_mm3 *= 2; }), k0);
  EXPECT_NE(changed([](Scene& t, LoadBasisOptions&) { t.problem.fixed_vertices.pop_back(); }), k0);
  EXPECT_NE(changed([](Scene& t, LoadBasisOptions&) { t.problem.mesh.rest_positions_World_mm(2, 5) += 1e-9; }), k0);
  EXPECT_NE(changed([](Scene& t, LoadBasisOptions&) { t.problem.mesh.tet_region[3] = 1; }), k0);
  EXPECT_NE(changed([](Scene&, LoadBasisOptions& o) { o.patches = 9; }), k0);
  EXPECT_NE(changed([](Scene&, LoadBasisOptions& o) { o.support_clusters = 3; }), k0);
  EXPECT_NE(changed([](Scene&, LoadBasisOptions& o) { o.gravity_modes = false; }), k0);
  // the fixed vertices are a set: their order does not matter; damping does not enter the basis
  EXPECT_EQ(changed([](Scene& t, LoadBasisOptions&) { std::reverse(t.problem.fixed_vertices.begin(), t.problem.fixed_vertices.end()); }), k0);
  EXPECT_EQ(changed([](Scene& t, LoadBasisOptions&) { t.problem.region_materials[0].damping_mass_per_s = 3; }), k0);
}

TEST(BasisCache, ChangedMaterialOrFixedSetBuildsANewBasis) {
  const Scene s = bar();
  const fs::path dir = fresh_dir("changed");
  const CachedBasis a = cached_load_basis(s, opts(), dir.string());
  Scene stiffer = s;
  stiffer.problem.region_materials[0].youngs_modulus_kPa = 10.0;
  const CachedBasis b = cached_load_basis(stiffer, opts(), dir.string());
  EXPECT_EQ(b.source, "built");
  EXPECT_NE(b.path, a.path);
  EXPECT_NE(a.basis->G, b.basis->G);
  Scene looser = s;
  looser.problem.fixed_vertices.resize(looser.problem.fixed_vertices.size() / 2);
  const CachedBasis c = cached_load_basis(looser, opts(), dir.string());
  EXPECT_EQ(c.source, "built");
  EXPECT_NE(c.path, a.path);
  EXPECT_NE(c.path, b.path);
  // each is loaded again afterwards
  EXPECT_EQ(cached_load_basis(stiffer, opts(), dir.string()).source, "loaded");
  EXPECT_EQ(cached_load_basis(looser, opts(), dir.string()).source, "loaded");
  EXPECT_EQ(cached_load_basis(s, opts(), dir.string()).source, "loaded");
  fs::remove_all(dir);
}

TEST(BasisCache, DamagedFilesAreRebuiltWithAWarning) {
  const Scene s = bar();
  const fs::path dir = fresh_dir("damaged");
  const CachedBasis good = cached_load_basis(s, opts(), dir.string());
  const std::string bytes = read(good.path);
  ASSERT_GT(bytes.size(), 1000u);
  struct Case {
    std::string name, bytes, message;
  };
  std::string flipped = bytes;
  flipped[bytes.size() - 100] ^= 0x10;
  std::string nan_file;
  {
    LoadBasis b = *good.basis;
    b.U(7, 3) = std::nan("");
    nan_file = serialize_load_basis(b, load_basis_key(s, opts()));
  }
  std::string other_key;
  {
    other_key = serialize_load_basis(*good.basis, std::string(32, '0'));
  }
  std::string other_size;
  {
    LoadBasis b = *good.basis;
    b.U.conservativeResize(b.U.rows() - 3, Eigen::NoChange);
    b.dofs -= 3;
    b.patch_of_vertex.pop_back();
    other_size = serialize_load_basis(b, load_basis_key(s, opts()));
  }
  const std::vector<Case> cases = {
      {"truncated", bytes.substr(0, bytes.size() / 2), "truncated"},
      {"header cut", bytes.substr(0, 40), "truncated"},
      {"empty", "", "magic"},
      {"corrupt payload", flipped, "checksum"},
      {"garbage header", bytes.substr(0, 16) + std::string(bytes.size() - 16, 'x'), "JSON"},
      {"NaN", nan_file, "NaN"},
      {"stale key", other_key, "stale"},
      {"other size", other_size, "stale"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    write(good.path, c.bytes);
    const CachedBasis r = cached_load_basis(s, opts(), dir.string());
    EXPECT_EQ(r.source, "built");
    ASSERT_FALSE(r.warnings.empty());
    EXPECT_TRUE(any_warning_names(r, c.message)) << r.warnings[0];
    expect_same(*r.basis, *good.basis, false);
    // rewritten: the next run loads it
    EXPECT_EQ(cached_load_basis(s, opts(), dir.string()).source, "loaded");
  }
  fs::remove_all(dir);
}

TEST(BasisCache, UnwritableFolderWarnsAndStillGivesTheBasis) {
  const Scene s = bar();
  const fs::path dir = fresh_dir("unwritable");
  // a regular file where the folder should be: it can be neither created nor written
  fs::create_directories(dir);
  write(dir / "file", "not a folder");
  const CachedBasis a = cached_load_basis(s, opts(), (dir / "file" / "cache").string());
  EXPECT_EQ(a.source, "built");
  ASSERT_NE(a.basis, nullptr);
  ASSERT_EQ(a.warnings.size(), 1u);
  EXPECT_NE(a.warnings[0].find("cannot create the folder"), std::string::npos) << a.warnings[0];
  // a folder without write permission (skipped as root, who may write anyway)
  const fs::path ro = dir / "ro";
  fs::create_directories(ro);
  fs::permissions(ro, fs::perms::owner_read | fs::perms::owner_exec);
  if (::geteuid() != 0) {
    const CachedBasis b = cached_load_basis(s, opts(), ro.string());
    EXPECT_EQ(b.source, "built");
    ASSERT_EQ(b.warnings.size(), 1u);
    EXPECT_NE(b.warnings[0].find("cannot write " + b.path), std::string::npos) << b.warnings[0];
    EXPECT_TRUE(fs::is_empty(ro));
  }
  fs::permissions(ro, fs::perms::owner_all);
  fs::remove_all(dir);
}

TEST(BasisCacheFile, RoundTripsAndRejectsEveryTruncation) {
  const Scene s = bar();
  const LoadBasis b = build_load_basis(s, opts());
  const std::string bytes = serialize_load_basis(b, "abc");
  expect_same(parse_load_basis(bytes, "abc", b.dofs, "x.bin"), b);
  for (std::size_t n = 0; n < bytes.size(); n += 1 + n / 7) EXPECT_THROW(parse_load_basis(bytes.substr(0, n), "abc", b.dofs, "x.bin"), LoadError) << n;
  EXPECT_THROW(parse_load_basis(bytes + "z", "abc", b.dofs, "x.bin"), LoadError);
  try {
    parse_load_basis(bytes, "abd", b.dofs, "cache/x.bin");
    FAIL();
  } catch (const LoadError& e) {
    EXPECT_NE(std::string(e.what()).find("cache/x.bin: key abc is not the scene's abd"), std::string::npos) << e.what();
  }
}

TEST(BasisCacheFile, FuzzSeedIsAValidFile) {
  // the fuzzer's seed (fuzz/basis_cache_seeds/tiny_basis.bin) must reach the accepting path
  const char* src = std::getenv("ARNAV_SOURCE_DIR");
  ASSERT_NE(src, nullptr);
  const std::string bytes = read(fs::path(src) / "host/register/fuzz/basis_cache_seeds/tiny_basis.bin");
  const LoadBasis b = parse_load_basis(bytes, "seed", 12, "tiny_basis.bin");
  EXPECT_EQ(b.modes(), 3);
  EXPECT_EQ(b.patch_of_vertex, (std::vector<int>{0, 0, -1, 0}));
  EXPECT_EQ(serialize_load_basis(b, "seed").size(), bytes.size());
}

TEST(BasisCacheFile, SizesThatAreNotWholeNumbersAreRefusedByName) {
  // A header whose sizes are floats, negative or huge (3e76 once reached an unchecked
  // float-to-integer conversion in the JSON library) is refused naming the field.
  const Scene s = bar();
  const LoadBasis b = build_load_basis(s, opts());
  const std::string good = serialize_load_basis(b, "abc");
  const std::string dofs = "\"dofs\": " + std::to_string(b.dofs);
  ASSERT_NE(good.find(dofs), std::string::npos);
  for (const std::string v : {"3e76", "12.5", "-12", "1e400"}) {
    std::string bytes = good;
    bytes.replace(bytes.find(dofs), dofs.size(), "\"dofs\": " + v);
    std::uint64_t hl = 0;  // the header length field follows the 8-byte magic
    std::memcpy(&hl, bytes.data() + 8, 8);
    hl += bytes.size() - good.size();
    std::memcpy(bytes.data() + 8, &hl, 8);
    try {
      parse_load_basis(bytes, "abc", b.dofs, "x.bin");
      ADD_FAILURE() << v;
    } catch (const LoadError& e) {
      const std::string what = e.what();
      EXPECT_TRUE(what.find("header field dofs is") != std::string::npos || what.find("not valid JSON") != std::string::npos) << v << ": " << what;
    }
  }
}
