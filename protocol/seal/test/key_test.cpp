// Key files (owner-only, exactly 32 bytes, never overwritten) and the `security:` setting.
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "protocol/seal/key.hpp"
#include "protocol/seal/security_config.hpp"
#include "protocol/testing/child_process.hpp"
#include "protocol/testing/error_of.hpp"

namespace arnav::seal {
namespace {

using arnav::testing::error_of;

namespace fs = std::filesystem;

struct TempDir {
  fs::path dir = fs::temp_directory_path() / ("seal_key_test_" + std::to_string(::getpid()));
  TempDir() { fs::create_directories(dir); }
  ~TempDir() { fs::remove_all(dir); }
};

TEST(Key, WrittenOwnerOnlyAndLoadedWithTheSameId) {
  TempDir t;
  const std::string path = (t.dir / "bus.key").string();
  const std::uint32_t id = write_new_key(path);
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  EXPECT_EQ(st.st_size, 32);
  const auto key = load_key(path);
  EXPECT_EQ(key->key_id(), id);
  EXPECT_EQ(key->key_id_hex().size(), 8u);
  // Two keys differ (random), and an existing key is never overwritten.
  EXPECT_NE(write_new_key((t.dir / "other.key").string()), id);
  EXPECT_NE(error_of([&] { write_new_key(path); }).find("exists already"), std::string::npos);
  EXPECT_EQ(load_key(path)->key_id(), id);
}

TEST(Key, RefusedWhenOthersCanReadItOrItIsNotAKey) {
  TempDir t;
  const std::string path = (t.dir / "bus.key").string();
  write_new_key(path);
  ::chmod(path.c_str(), 0644);
  std::string e = error_of([&] { load_key(path); });
  EXPECT_NE(e.find(path + ": the key file has mode 644"), std::string::npos) << e;
  EXPECT_NE(e.find("chmod 600"), std::string::npos) << e;
  ::chmod(path.c_str(), 0640);
  EXPECT_NE(error_of([&] { load_key(path); }).find("mode 640"), std::string::npos);
  ::chmod(path.c_str(), 0400);
  EXPECT_EQ(error_of([&] { load_key(path); }), "");

  const std::string short_key = (t.dir / "short.key").string();
  std::ofstream(short_key) << "0123456789";
  ::chmod(short_key.c_str(), 0600);
  EXPECT_NE(error_of([&] { load_key(short_key); }).find("has 10 bytes, a key has exactly 32"), std::string::npos);

  e = error_of([&] { load_key((t.dir / "missing.key").string()); });
  EXPECT_NE(e.find("cannot open the key file"), std::string::npos);
  EXPECT_NE(e.find("arnav-keygen"), std::string::npos);
  EXPECT_NE(error_of([&] { load_key(t.dir.string()); }).find("not a regular file"), std::string::npos);
}

SecuritySettings parse(const std::string& yaml, const fs::path& base = "/cfg") {
  const YAML::Node root = YAML::Load(yaml);
  return parse_security(root["security"], "app.yaml", base);
}

TEST(SecuritySetting, OffSealedAndMissing) {
  EXPECT_EQ(parse("security: off\n").mode, SecuritySettings::Mode::Off);
  const SecuritySettings s = parse("port: sim\nsecurity: {key_file: keys/bus.key, max_age_ms: 500}\n");
  EXPECT_EQ(s.mode, SecuritySettings::Mode::Sealed);
  EXPECT_EQ(s.key_file, "/cfg/keys/bus.key");
  EXPECT_EQ(s.max_age_ms, 500);
  EXPECT_EQ(s.line, 2);
  EXPECT_EQ(parse("security: {key_file: /k/bus.key}\n").key_file, "/k/bus.key");
  EXPECT_EQ(parse("port: sim\n").mode, SecuritySettings::Mode::Missing);
  const std::string missing = error_of([] { resolve_security(parse("port: sim\n")); });
  EXPECT_NE(missing.find("app.yaml: key 'security': missing"), std::string::npos) << missing;
  EXPECT_NE(missing.find("security: off"), std::string::npos);
  EXPECT_FALSE(resolve_security(parse("security: off\n")).sealed());
  EXPECT_NE(resolve_security(parse("security: off\n")).describe().find("security: OFF"), std::string::npos);
}

TEST(SecuritySetting, BadValuesNameTheLine) {
  EXPECT_NE(error_of([] { parse("a: 1\nsecurity: on\n"); }).find("app.yaml:2: key 'security': 'on' is not a setting"), std::string::npos);
  EXPECT_NE(error_of([] { parse("security: {keyfile: x}\n"); }).find("key 'security.keyfile': unknown key"), std::string::npos);
  EXPECT_NE(error_of([] { parse("security: {max_age_ms: 5}\n"); }).find("key 'security.key_file': missing"), std::string::npos);
  EXPECT_NE(error_of([] { parse("security: {key_file: k, max_age_ms: 0}\n"); }).find("must be between 1 and 600000"), std::string::npos);
  EXPECT_NE(error_of([] { parse("security: [a]\n"); }).find("expected a mapping"), std::string::npos);
  TempDir t;
  const std::string e = error_of([&] { resolve_security(parse("security: {key_file: none.key}\n", t.dir)); });
  EXPECT_NE(e.find("app.yaml:1: key 'security.key_file': "), std::string::npos) << e;
}

TEST(SecuritySetting, CommandLine) {
  EXPECT_FALSE(security_from_cli("", "off", "prog").sealed());
  EXPECT_NE(error_of([] { security_from_cli("", "", "prog"); }).find("prog: the bus is sealed: give --key FILE"), std::string::npos);
  EXPECT_NE(error_of([] { security_from_cli("", "on", "prog"); }).find("--security takes only 'off'"), std::string::npos);
  EXPECT_NE(error_of([] { security_from_cli("k", "off", "prog"); }).find("not both"), std::string::npos);
  TempDir t;
  const std::string path = (t.dir / "bus.key").string();
  const auto id = write_new_key(path);
  const BusSecurity b = security_from_cli(path, "", "prog");
  ASSERT_TRUE(b.sealed());
  EXPECT_EQ(b.key->key_id(), id);
  EXPECT_NE(b.describe().find("key id " + key_id_hex(id)), std::string::npos);
}

TEST(Keygen, MakesAKeyAndRefusesToOverwrite) {
  TempDir t;
  const std::string exe = arnav::testing::binary_path("protocol/seal/arnav-keygen");
  const std::string path = (t.dir / "bus.key").string();
  auto r = arnav::testing::run_command(exe + " " + path);
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_NE(r.output.find("key id " + load_key(path)->key_id_hex()), std::string::npos) << r.output;
  r = arnav::testing::run_command(exe + " " + path);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.output.find("exists already"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace arnav::seal
