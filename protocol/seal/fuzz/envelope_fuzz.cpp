// libFuzzer target: the envelope parser and the receiver on arbitrary bytes (what anyone on
// the network can send). Never reads out of bounds, never accepts what it did not seal,
// and whatever it seals itself opens to the same bytes exactly once.
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <string>

#include "protocol/seal/channel_guard.hpp"

namespace {
std::shared_ptr<const arnav::seal::SessionKey> fuzz_key() {
  std::array<std::uint8_t, arnav::seal::kKeyBytes> b{};
  for (std::size_t i = 0; i < b.size(); ++i) b[i] = static_cast<std::uint8_t>(i * 7 + 1);
  return std::make_shared<const arnav::seal::SessionKey>(b);
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace arnav::seal;
  static const auto key = fuzz_key();
  static Opener opener(key);
  static Sealer sealer(key);
  const std::span<const std::uint8_t> bytes(data, size);
  std::vector<std::uint8_t> plain;
  const std::string channel = size > 0 ? "ARNAV_POSE_" + std::to_string(data[0] % 4) : "ARNAV_EVENT";
  const ParseResult parsed = parse_envelope(bytes);
  if (parsed.envelope && parsed.envelope->sealed.size() + kHeaderBytes != size) std::abort();
  const Verdict v = opener.open(channel, bytes, 1'700'000'000'000'000, plain);
  // Only messages sealed with the key open, and the fuzzer cannot forge a Poly1305 tag.
  if (v == Verdict::Accepted) std::abort();
  if (!plain.empty()) std::abort();
  // The input as a plaintext: seals, opens once, then reads as a replay.
  std::vector<std::uint8_t> env, back;
  sealer.seal(channel, bytes, 1'700'000'000'000'000, env);
  if (opener.open(channel, env, 1'700'000'000'000'000, back) != Verdict::Accepted || back.size() != size ||
      (size > 0 && std::memcmp(back.data(), data, size) != 0))
    std::abort();
  if (opener.open(channel, env, 1'700'000'000'000'000, back) != Verdict::Replayed) std::abort();
  return 0;
}
