#pragma once
// OpenIGTLink framing read by hand (docs/igtl.md): the 58-byte header of protocol header
// versions 1 and 2, the version-2 extended header and metadata bounds, and a stream reader
// that cuts a TCP byte stream into messages. Debian's libopenigtlink 1.11 unpacks only
// version-1 headers (a version-2 STATUS, which 3D Slicer sends on connect, leaves its type
// and size empty and the stream out of step), so arnav-igtl never hands it a raw stream:
// this reader frames every message and skips the bodies of types it does not handle.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace arnav::igtl {

inline constexpr std::size_t kHeaderSize = 58;
inline constexpr std::size_t kExtendedHeaderMinSize = 12;  // version 2: ext header size .. message id

struct Header {
  std::uint16_t version = 0;      // 1 or 2 (3 is read like 2)
  std::string type;               // "TRANSFORM", "STT_TDATA", ... (NUL padding removed)
  std::string device_name;
  std::uint64_t timestamp = 0;    // 32.32 fixed point seconds since the Unix epoch (UTC)
  std::uint64_t body_size = 0;
  std::uint64_t crc = 0;          // CRC-64 (ECMA-182) of the body
};

// Parses one header. Returns nullopt with `why` filled when the bytes cannot be an
// OpenIGTLink header (unknown version, type with non-printable characters or empty,
// device name not printable, body size above max_body_bytes): the stream is lost.
std::optional<Header> parse_header(std::span<const std::uint8_t, kHeaderSize> bytes, std::uint64_t max_body_bytes,
                                   std::string& why);

// Writes a header (big endian) into out (kHeaderSize bytes). Names longer than their
// fields (type 12, device 20) are cut.
void write_header(const Header& header, std::uint8_t* out);

// The content of a body: for version 1 the whole body; for version 2 the part between the
// extended header and the metadata. nullopt (with why) when the extended header is
// inconsistent with the body size.
std::optional<std::span<const std::uint8_t>> body_content(const Header& header, std::span<const std::uint8_t> body,
                                                          std::string& why);

// CRC-64 of a body as OpenIGTLink computes it.
std::uint64_t body_crc(std::span<const std::uint8_t> body);

struct Message {
  Header header;
  std::vector<std::uint8_t> body;  // empty when the type was not kept (skipped)
  bool body_kept = false;
};

// Cuts a byte stream into messages. Bodies of the types in `keep_types` are collected
// (up to max_kept_body_bytes each); others are skipped byte by byte without being stored,
// whatever their size up to max_body_bytes. After an error the reader stays failed.
class StreamReader {
 public:
  StreamReader(std::vector<std::string> keep_types, std::uint64_t max_kept_body_bytes, std::uint64_t max_body_bytes);

  // Consumes bytes; complete messages are queued for next().
  void feed(std::span<const std::uint8_t> bytes);
  std::optional<Message> next();

  bool failed() const { return !error_.empty(); }
  const std::string& error() const { return error_; }
  std::uint64_t messages_read() const { return messages_read_; }
  std::uint64_t messages_skipped() const { return messages_skipped_; }

 private:
  bool keeps(const std::string& type) const;

  std::vector<std::string> keep_types_;
  std::uint64_t max_kept_body_bytes_;
  std::uint64_t max_body_bytes_;
  std::uint8_t header_bytes_[kHeaderSize] = {};
  std::size_t header_filled_ = 0;
  std::optional<Header> current_;
  std::uint64_t body_left_ = 0;
  Message building_;
  std::vector<Message> ready_;
  std::size_t ready_pos_ = 0;
  std::string error_;
  std::uint64_t messages_read_ = 0;
  std::uint64_t messages_skipped_ = 0;
};

}  // namespace arnav::igtl
