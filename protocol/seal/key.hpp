#pragma once
// The bus session key: 32 random bytes in a file only its owner may read (mode 0600 or
// 0400, owned by the user running the program). docs/protocol.md, "Sealed bus".
#include <array>
#include <cstdint>
#include <memory>
#include <stdexcept>
#include <string>

namespace arnav::seal {

inline constexpr std::size_t kKeyBytes = 32;

// A key file that cannot be used: the message names the file and what to do.
class KeyError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class SessionKey {
 public:
  explicit SessionKey(const std::array<std::uint8_t, kKeyBytes>& bytes);
  ~SessionKey();
  SessionKey(const SessionKey&) = delete;
  SessionKey& operator=(const SessionKey&) = delete;

  const std::uint8_t* data() const { return bytes_.data(); }
  // 4 bytes derived from the key (BLAKE2b, its own context): carried in every envelope so a
  // log opened with the wrong key says so; reveals nothing usable about the key.
  std::uint32_t key_id() const { return key_id_; }
  std::string key_id_hex() const;

 private:
  std::array<std::uint8_t, kKeyBytes> bytes_;
  std::uint32_t key_id_;
};

std::string key_id_hex(std::uint32_t id);

// Reads a key file. Refuses (KeyError naming the path and the fix): a missing file, a
// file that is not a regular file, one that group or others may read or write, one owned
// by another user, and a file that is not exactly 32 bytes.
std::shared_ptr<const SessionKey> load_key(const std::string& path);

// Writes 32 fresh random bytes (libsodium randombytes) to a new file created with mode
// 0600; refuses to overwrite an existing file. Returns the new key's id.
std::uint32_t write_new_key(const std::string& path);

// libsodium's sodium_init (idempotent, thread-safe); throws std::runtime_error if it fails.
void init_sodium();

}  // namespace arnav::seal
