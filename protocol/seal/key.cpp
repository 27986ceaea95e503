#include "protocol/seal/key.hpp"

#include <sodium.h>

#include <cerrno>
#include <cstdio>
#include <cstring>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

namespace arnav::seal {

namespace {
std::uint32_t derive_key_id(const std::uint8_t* key) {
  static const char kContext[] = "arnav bus key id v1";
  std::uint8_t out[crypto_generichash_BYTES_MIN];
  crypto_generichash(out, sizeof out, reinterpret_cast<const unsigned char*>(kContext), sizeof kContext - 1, key, kKeyBytes);
  return (std::uint32_t{out[0]} << 24) | (std::uint32_t{out[1]} << 16) | (std::uint32_t{out[2]} << 8) | out[3];
}

std::string errno_text() { return std::strerror(errno); }
}  // namespace

void init_sodium() {
  if (sodium_init() < 0) throw std::runtime_error("libsodium could not be initialised (sodium_init failed)");
}

SessionKey::SessionKey(const std::array<std::uint8_t, kKeyBytes>& bytes) : bytes_(bytes) {
  init_sodium();
  key_id_ = derive_key_id(bytes_.data());
}

SessionKey::~SessionKey() { sodium_memzero(bytes_.data(), bytes_.size()); }

std::string key_id_hex(std::uint32_t id) {
  char buf[9];
  std::snprintf(buf, sizeof buf, "%08x", id);
  return buf;
}

std::string SessionKey::key_id_hex() const { return seal::key_id_hex(key_id_); }

std::shared_ptr<const SessionKey> load_key(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
  if (fd < 0)
    throw KeyError(path + ": cannot open the key file (" + errno_text() + "); make one with: arnav-keygen " + path);
  struct Closer {
    int fd;
    ~Closer() { ::close(fd); }
  } closer{fd};
  struct stat st {};
  if (::fstat(fd, &st) != 0) throw KeyError(path + ": cannot stat the key file (" + errno_text() + ")");
  if (!S_ISREG(st.st_mode)) throw KeyError(path + ": the key file is not a regular file");
  if ((st.st_mode & 077) != 0) {
    char mode[8];
    std::snprintf(mode, sizeof mode, "%03o", static_cast<unsigned>(st.st_mode & 0777));
    throw KeyError(path + ": the key file has mode " + mode + ": group or others may read it, so the key must be taken as leaked. "
                   "Make a new key (arnav-keygen), or if it never left this machine: chmod 600 " + path);
  }
  if (st.st_uid != ::geteuid())
    throw KeyError(path + ": the key file belongs to user id " + std::to_string(st.st_uid) + ", not to the user running this program (" +
                   std::to_string(::geteuid()) + "): copy it with install -m 600");
  if (st.st_size != static_cast<off_t>(kKeyBytes))
    throw KeyError(path + ": the key file has " + std::to_string(st.st_size) + " bytes, a key has exactly " + std::to_string(kKeyBytes) +
                   " (raw random bytes, made by arnav-keygen)");
  std::array<std::uint8_t, kKeyBytes> bytes{};
  std::size_t got = 0;
  while (got < kKeyBytes) {
    const ssize_t n = ::read(fd, bytes.data() + got, kKeyBytes - got);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw KeyError(path + ": cannot read the key file (" + (n < 0 ? errno_text() : std::string("short file")) + ")");
    got += static_cast<std::size_t>(n);
  }
  auto key = std::make_shared<const SessionKey>(bytes);
  sodium_memzero(bytes.data(), bytes.size());
  return key;
}

std::uint32_t write_new_key(const std::string& path) {
  init_sodium();
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC | O_NOFOLLOW, 0600);
  if (fd < 0)
    throw KeyError(path + ": cannot create the key file (" + errno_text() + ")" +
                   (errno == EEXIST ? ": it exists already; a key is never overwritten (remove it first if you mean to replace it)" : ""));
  std::array<std::uint8_t, kKeyBytes> bytes{};
  randombytes_buf(bytes.data(), bytes.size());
  std::size_t put = 0;
  bool ok = true;
  while (put < kKeyBytes) {
    const ssize_t n = ::write(fd, bytes.data() + put, kKeyBytes - put);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      ok = false;
      break;
    }
    put += static_cast<std::size_t>(n);
  }
  // umask may have narrowed the mode further; never widen it, but make sure it is owner-only.
  ok = ok && ::fchmod(fd, 0600) == 0 && ::fsync(fd) == 0;
  ::close(fd);
  const std::uint32_t id = SessionKey(bytes).key_id();
  sodium_memzero(bytes.data(), bytes.size());
  if (!ok) {
    ::unlink(path.c_str());
    throw KeyError(path + ": cannot write the key file (" + errno_text() + ")");
  }
  return id;
}

}  // namespace arnav::seal
