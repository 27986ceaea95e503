#pragma once
// The sealed-message envelope (docs/protocol.md, "Sealed bus"). Every LCM message on a
// sealed bus is the encoded LCM message sealed with XChaCha20-Poly1305 (libsodium, IETF
// construction), laid out big-endian:
//   0  magic "ARNS"          4 bytes
//   4  version (1)           1
//   5  suite (1 = XChaCha20-Poly1305) 1
//   6  reserved (0)          2
//   8  key id                4   (SessionKey::key_id: says "wrong key" instead of "forged")
//  12  sender id            16   (random per sender start: a restart never reuses a nonce)
//  28  counter               8   (per sender, from 1, +1 per message)
//  36  time_wall_us          8   (sender's CLOCK_REALTIME when sealed)
//  44  ciphertext            n   (the LCM message)
//  44+n tag                 16
// Nonce (24 bytes) = sender id || counter. Associated data = the 44 header bytes || the
// LCM channel name: a message moved to another channel, or with any header byte changed,
// does not open.
#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "protocol/seal/key.hpp"

namespace arnav::seal {

inline constexpr std::array<std::uint8_t, 4> kMagic = {'A', 'R', 'N', 'S'};
inline constexpr std::uint8_t kVersion = 1;
inline constexpr std::uint8_t kSuiteXChaCha20Poly1305 = 1;
inline constexpr std::size_t kHeaderBytes = 44;
inline constexpr std::size_t kTagBytes = 16;
inline constexpr std::size_t kOverheadBytes = kHeaderBytes + kTagBytes;
inline constexpr std::size_t kSenderIdBytes = 16;
// LCM's own limit on one message (udpm fragments up to 4 GB in theory; this bounds work).
inline constexpr std::size_t kMaxPlaintextBytes = 64u << 20;

using SenderId = std::array<std::uint8_t, kSenderIdBytes>;

struct EnvelopeHeader {
  std::uint32_t key_id = 0;
  SenderId sender{};
  std::uint64_t counter = 0;
  std::int64_t time_wall_us = 0;
};

// Why bytes are not an envelope (before any cryptography).
enum class ParseError { NotSealed, BadVersion, Truncated, TooLarge };
const char* to_string(ParseError e);

// A sender id as printed by the tools and the host: its first 8 bytes in hex (16 digits).
std::string sender_hex(const SenderId& id);

struct ParsedEnvelope {
  EnvelopeHeader header;
  std::span<const std::uint8_t> header_bytes;  // the 44 bytes (associated data, first part)
  std::span<const std::uint8_t> sealed;        // ciphertext || tag
  std::size_t plaintext_size() const { return sealed.size() - kTagBytes; }
};

// True when the bytes start with the envelope magic (a sealed message, perhaps damaged).
bool looks_sealed(std::span<const std::uint8_t> bytes);

// Reads the header; never reads past bytes. Returns the error instead of throwing.
struct ParseResult {
  std::optional<ParsedEnvelope> envelope;
  ParseError error = ParseError::NotSealed;
};
ParseResult parse_envelope(std::span<const std::uint8_t> bytes);

// Seals plaintext into out (resized to plaintext.size() + kOverheadBytes; reuses its capacity).
void seal_message(const SessionKey& key, const EnvelopeHeader& header, std::string_view channel,
                  std::span<const std::uint8_t> plaintext, std::vector<std::uint8_t>& out);

// Authenticates and decrypts into plain (resized to the plaintext size). False when the tag
// does not verify with this key, header and channel: nothing is written that may be used.
bool open_message(const SessionKey& key, const ParsedEnvelope& envelope, std::string_view channel, std::vector<std::uint8_t>& plain);

// Fresh random sender id (libsodium randombytes).
SenderId random_sender_id();

}  // namespace arnav::seal
