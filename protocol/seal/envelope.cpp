#include "protocol/seal/envelope.hpp"

#include <cstdio>

#include <sodium.h>

#include <algorithm>
#include <cstring>

namespace arnav::seal {

namespace {

static_assert(crypto_aead_xchacha20poly1305_ietf_KEYBYTES == kKeyBytes);
static_assert(crypto_aead_xchacha20poly1305_ietf_NPUBBYTES == kSenderIdBytes + 8);
static_assert(crypto_aead_xchacha20poly1305_ietf_ABYTES == kTagBytes);

void put_u32(std::uint8_t* p, std::uint32_t v) {
  for (int i = 3; i >= 0; --i, v >>= 8) p[i] = static_cast<std::uint8_t>(v & 0xff);
}
void put_u64(std::uint8_t* p, std::uint64_t v) {
  for (int i = 7; i >= 0; --i, v >>= 8) p[i] = static_cast<std::uint8_t>(v & 0xff);
}
std::uint32_t get_u32(const std::uint8_t* p) {
  std::uint32_t v = 0;
  for (int i = 0; i < 4; ++i) v = (v << 8) | p[i];
  return v;
}
std::uint64_t get_u64(const std::uint8_t* p) {
  std::uint64_t v = 0;
  for (int i = 0; i < 8; ++i) v = (v << 8) | p[i];
  return v;
}

void write_header(const EnvelopeHeader& h, std::uint8_t* p) {
  std::memcpy(p, kMagic.data(), kMagic.size());
  p[4] = kVersion;
  p[5] = kSuiteXChaCha20Poly1305;
  p[6] = 0;
  p[7] = 0;
  put_u32(p + 8, h.key_id);
  std::memcpy(p + 12, h.sender.data(), kSenderIdBytes);
  put_u64(p + 28, h.counter);
  put_u64(p + 36, static_cast<std::uint64_t>(h.time_wall_us));
}

std::array<std::uint8_t, 24> nonce_of(const EnvelopeHeader& h) {
  std::array<std::uint8_t, 24> n{};
  std::memcpy(n.data(), h.sender.data(), kSenderIdBytes);
  put_u64(n.data() + kSenderIdBytes, h.counter);
  return n;
}

// Associated data: header bytes then channel name, in one buffer (libsodium takes one AD).
void build_ad(std::span<const std::uint8_t> header, std::string_view channel, std::vector<std::uint8_t>& ad) {
  ad.resize(header.size() + channel.size());
  std::memcpy(ad.data(), header.data(), header.size());
  if (!channel.empty()) std::memcpy(ad.data() + header.size(), channel.data(), channel.size());
}

thread_local std::vector<std::uint8_t> t_ad;  // reused: no allocation per message once warm

}  // namespace

std::string sender_hex(const SenderId& id) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%02x%02x%02x%02x%02x%02x%02x%02x", id[0], id[1], id[2], id[3], id[4], id[5], id[6], id[7]);
  return buf;
}

const char* to_string(ParseError e) {
  switch (e) {
    case ParseError::NotSealed: return "not sealed (no ARNS envelope)";
    case ParseError::BadVersion: return "unknown envelope version or cipher suite";
    case ParseError::Truncated: return "envelope shorter than its header and tag";
    case ParseError::TooLarge: return "envelope larger than the 64 MiB limit";
  }
  return "?";
}

bool looks_sealed(std::span<const std::uint8_t> bytes) {
  return bytes.size() >= kMagic.size() && std::equal(kMagic.begin(), kMagic.end(), bytes.begin());
}

ParseResult parse_envelope(std::span<const std::uint8_t> bytes) {
  ParseResult r;
  if (!looks_sealed(bytes)) return r;
  if (bytes.size() < kOverheadBytes) {
    r.error = ParseError::Truncated;
    return r;
  }
  const std::uint8_t* p = bytes.data();
  if (p[4] != kVersion || p[5] != kSuiteXChaCha20Poly1305 || p[6] != 0 || p[7] != 0) {
    r.error = ParseError::BadVersion;
    return r;
  }
  if (bytes.size() - kOverheadBytes > kMaxPlaintextBytes) {
    r.error = ParseError::TooLarge;
    return r;
  }
  ParsedEnvelope e;
  e.header.key_id = get_u32(p + 8);
  std::memcpy(e.header.sender.data(), p + 12, kSenderIdBytes);
  e.header.counter = get_u64(p + 28);
  e.header.time_wall_us = static_cast<std::int64_t>(get_u64(p + 36));
  e.header_bytes = bytes.subspan(0, kHeaderBytes);
  e.sealed = bytes.subspan(kHeaderBytes);
  r.envelope = e;
  return r;
}

void seal_message(const SessionKey& key, const EnvelopeHeader& header, std::string_view channel,
                  std::span<const std::uint8_t> plaintext, std::vector<std::uint8_t>& out) {
  out.resize(plaintext.size() + kOverheadBytes);
  write_header(header, out.data());
  build_ad(std::span<const std::uint8_t>(out.data(), kHeaderBytes), channel, t_ad);
  const auto nonce = nonce_of(header);
  unsigned long long sealed_len = 0;
  crypto_aead_xchacha20poly1305_ietf_encrypt(out.data() + kHeaderBytes, &sealed_len, plaintext.data(), plaintext.size(), t_ad.data(),
                                             t_ad.size(), nullptr, nonce.data(), key.data());
}

bool open_message(const SessionKey& key, const ParsedEnvelope& envelope, std::string_view channel, std::vector<std::uint8_t>& plain) {
  build_ad(envelope.header_bytes, channel, t_ad);
  const auto nonce = nonce_of(envelope.header);
  plain.resize(envelope.plaintext_size());
  unsigned long long plain_len = 0;
  const int rc = crypto_aead_xchacha20poly1305_ietf_decrypt(plain.data(), &plain_len, nullptr, envelope.sealed.data(), envelope.sealed.size(),
                                                            t_ad.data(), t_ad.size(), nonce.data(), key.data());
  if (rc != 0) {
    plain.clear();
    return false;
  }
  plain.resize(static_cast<std::size_t>(plain_len));
  return true;
}

SenderId random_sender_id() {
  init_sodium();
  SenderId id{};
  randombytes_buf(id.data(), id.size());
  return id;
}

}  // namespace arnav::seal
