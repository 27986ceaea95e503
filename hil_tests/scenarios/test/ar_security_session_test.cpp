// The sealed-bus steps of scripts/demo's AR session (ar_bench.sh: ar_make_key,
// ar_start_attacker, ar_finish, ar_print_security) on their own, in a short sealed session
// (ar_security_session.sh: synthetic camera, 6 s): the key made by arnav-keygen, the host
// and the appliance sealed, arnav-bus-attacker injecting forged, replayed and bit-flipped
// messages; the `security:` line counts them from the host's counters and says 0 accepted;
// the banner was shown; the replay of the log drops them again (docs/security.md).
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <regex>

#include <nlohmann/json.hpp>

#include "hil_tests/bench/bench_required.hpp"
#include "protocol/testing/child_process.hpp"

namespace {

TEST(ArSecuritySession, AttacksCountedByTheHostNoneAccepted) {
  const std::filesystem::path out = std::filesystem::temp_directory_path() / ("arnav-ar-security-" + std::to_string(::getpid()));
  std::filesystem::remove_all(out);
  const auto r = arnav::testing::run_command(arnav::testing::source_dir() + "/hil_tests/scenarios/ar_security_session.sh " +
                                             arnav::testing::required_env("ARNAV_BINARY_DIR") + " " + out.string());
  ARNAV_BENCH_OR_SKIP(r.code == 77 ? r.output : std::string());
  std::cout << r.output;
  ASSERT_EQ(r.code, 0) << r.output;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(r.output, m, std::regex(R"(security: (\d+) injected \(forged (\d+)/replayed (\d+)/tampered (\d+)/unsealed (\d+)\), 0 accepted)")))
      << r.output;
  std::ifstream in(out / "host.json");
  const nlohmann::json host = nlohmann::json::parse(in);
  const nlohmann::json& sec = host["security"];
  // The line is the host's counters, every kind present.
  EXPECT_EQ(std::stoull(m[1]), sec["dropped"].get<std::uint64_t>());
  EXPECT_EQ(std::stoull(m[2]), sec["forged"].get<std::uint64_t>());
  EXPECT_EQ(std::stoull(m[3]), sec["replayed"].get<std::uint64_t>());
  EXPECT_EQ(std::stoull(m[4]), sec["tampered"].get<std::uint64_t>());
  for (std::size_t i = 2; i <= 5; ++i) EXPECT_GT(std::stoull(m[i]), 0u) << r.output;
  // The attacker stopped before the host: the host counted what it sent (UDP on a loaded machine may lose a few).
  std::ifstream attack_in(out / "attack.json");
  const nlohmann::json attack = nlohmann::json::parse(attack_in);
  EXPECT_LE(sec["dropped"].get<std::uint64_t>(), attack["total"].get<std::uint64_t>());
  EXPECT_GE(static_cast<double>(sec["dropped"].get<std::uint64_t>()), 0.95 * attack["total"].get<double>());
  EXPECT_NE(r.output.find("all announced by arnav-appliance; 0 accepted twice"), std::string::npos) << r.output;
  EXPECT_GT(host["navigation"]["flags"]["security_rejected"]["frames"].get<int>(), 0);
  EXPECT_NE(r.output.find("replay of the session's log with the key: "), std::string::npos) << r.output;
  EXPECT_EQ(std::filesystem::status(out / "bus.key").permissions() & std::filesystem::perms::all, std::filesystem::perms::owner_read | std::filesystem::perms::owner_write);
  if (!std::getenv("ARNAV_HIL_KEEP")) std::filesystem::remove_all(out);
}

}  // namespace
