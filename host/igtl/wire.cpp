#include "host/igtl/wire.hpp"

#include <algorithm>
#include <array>

namespace arnav::igtl {
namespace {

std::uint64_t read_be(const std::uint8_t* p, int bytes) {
  std::uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v = (v << 8) | p[i];
  return v;
}

void write_be(std::uint8_t* p, std::uint64_t v, int bytes) {
  for (int i = bytes - 1; i >= 0; --i) {
    p[i] = static_cast<std::uint8_t>(v & 0xffu);
    v >>= 8;
  }
}

// A fixed-size NUL-padded field: the text before the first NUL; false when a character
// before it is not printable ASCII or a non-NUL byte follows the first NUL.
bool read_name(const std::uint8_t* p, std::size_t size, std::string& out) {
  out.clear();
  std::size_t i = 0;
  for (; i < size && p[i] != 0; ++i) {
    if (p[i] < 0x20 || p[i] > 0x7e) return false;
    out.push_back(static_cast<char>(p[i]));
  }
  for (; i < size; ++i)
    if (p[i] != 0) return false;
  return true;
}

constexpr std::uint64_t kCrcPolynomial = 0x42F0E1EBA9EA3693ull;  // ECMA-182, not reflected

constexpr std::array<std::uint64_t, 256> make_crc_table() {
  std::array<std::uint64_t, 256> table{};
  for (std::uint64_t i = 0; i < 256; ++i) {
    std::uint64_t crc = i << 56;
    for (int bit = 0; bit < 8; ++bit) crc = (crc & (1ull << 63)) ? (crc << 1) ^ kCrcPolynomial : crc << 1;
    table[i] = crc;
  }
  return table;
}
constexpr auto kCrcTable = make_crc_table();

}  // namespace

std::optional<Header> parse_header(std::span<const std::uint8_t, kHeaderSize> b, std::uint64_t max_body_bytes, std::string& why) {
  Header h;
  h.version = static_cast<std::uint16_t>(read_be(b.data(), 2));
  if (h.version < 1 || h.version > 3) {
    why = "header version " + std::to_string(h.version) + " (OpenIGTLink has 1, 2 and 3): not an OpenIGTLink stream";
    return std::nullopt;
  }
  if (!read_name(b.data() + 2, 12, h.type) || h.type.empty()) {
    why = "message type is empty or not printable ASCII: not an OpenIGTLink stream";
    return std::nullopt;
  }
  if (!read_name(b.data() + 14, 20, h.device_name)) {
    why = "device name of a " + h.type + " message is not printable ASCII";
    return std::nullopt;
  }
  h.timestamp = read_be(b.data() + 34, 8);
  h.body_size = read_be(b.data() + 42, 8);
  h.crc = read_be(b.data() + 50, 8);
  if (h.body_size > max_body_bytes) {
    why = h.type + " message body of " + std::to_string(h.body_size) + " bytes is above the limit of " + std::to_string(max_body_bytes);
    return std::nullopt;
  }
  return h;
}

void write_header(const Header& h, std::uint8_t* out) {
  std::fill(out, out + kHeaderSize, std::uint8_t{0});
  write_be(out, h.version, 2);
  std::copy_n(h.type.begin(), std::min<std::size_t>(h.type.size(), 12), out + 2);
  std::copy_n(h.device_name.begin(), std::min<std::size_t>(h.device_name.size(), 20), out + 14);
  write_be(out + 34, h.timestamp, 8);
  write_be(out + 42, h.body_size, 8);
  write_be(out + 50, h.crc, 8);
}

std::optional<std::span<const std::uint8_t>> body_content(const Header& h, std::span<const std::uint8_t> body, std::string& why) {
  if (h.version < 2) return body;
  if (body.size() < kExtendedHeaderMinSize) {
    why = "version-2 " + h.type + " body of " + std::to_string(body.size()) + " bytes is shorter than its extended header";
    return std::nullopt;
  }
  const std::uint64_t ext_size = read_be(body.data(), 2);
  const std::uint64_t meta_header_size = read_be(body.data() + 2, 2);
  const std::uint64_t meta_size = read_be(body.data() + 4, 4);
  if (ext_size < kExtendedHeaderMinSize || ext_size + meta_header_size + meta_size > body.size()) {
    why = "version-2 " + h.type + " extended header (size " + std::to_string(ext_size) + ", metadata " +
          std::to_string(meta_header_size) + "+" + std::to_string(meta_size) + ") does not fit its body of " +
          std::to_string(body.size()) + " bytes";
    return std::nullopt;
  }
  return body.subspan(ext_size, body.size() - ext_size - meta_header_size - meta_size);
}

std::uint64_t body_crc(std::span<const std::uint8_t> body) {
  std::uint64_t crc = 0;
  for (const std::uint8_t byte : body) crc = kCrcTable[((crc >> 56) ^ byte) & 0xffu] ^ (crc << 8);
  return crc;
}

StreamReader::StreamReader(std::vector<std::string> keep_types, std::uint64_t max_kept_body_bytes, std::uint64_t max_body_bytes)
    : keep_types_(std::move(keep_types)), max_kept_body_bytes_(max_kept_body_bytes), max_body_bytes_(max_body_bytes) {}

bool StreamReader::keeps(const std::string& type) const {
  return std::find(keep_types_.begin(), keep_types_.end(), type) != keep_types_.end();
}

void StreamReader::feed(std::span<const std::uint8_t> bytes) {
  while (!bytes.empty() && error_.empty()) {
    if (!current_) {
      const std::size_t n = std::min(bytes.size(), kHeaderSize - header_filled_);
      std::copy_n(bytes.begin(), n, header_bytes_ + header_filled_);
      header_filled_ += n;
      bytes = bytes.subspan(n);
      if (header_filled_ < kHeaderSize) return;
      header_filled_ = 0;
      current_ = parse_header(std::span<const std::uint8_t, kHeaderSize>(header_bytes_, kHeaderSize), max_body_bytes_, error_);
      if (!current_) return;
      building_ = Message{*current_, {}, keeps(current_->type)};
      if (building_.body_kept && current_->body_size > max_kept_body_bytes_) {
        error_ = current_->type + " message body of " + std::to_string(current_->body_size) + " bytes is above the limit of " +
                 std::to_string(max_kept_body_bytes_) + " for a request";
        return;
      }
      if (building_.body_kept) building_.body.reserve(current_->body_size);
      body_left_ = current_->body_size;
    }
    const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(bytes.size(), body_left_));
    if (building_.body_kept) building_.body.insert(building_.body.end(), bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(n));
    bytes = bytes.subspan(n);
    body_left_ -= n;
    if (body_left_ == 0) {
      ++messages_read_;
      if (!building_.body_kept) ++messages_skipped_;
      ready_.push_back(std::move(building_));
      building_ = Message{};
      current_.reset();
    }
  }
}

std::optional<Message> StreamReader::next() {
  if (ready_pos_ >= ready_.size()) {
    ready_.clear();
    ready_pos_ = 0;
    return std::nullopt;
  }
  return std::move(ready_[ready_pos_++]);
}

}  // namespace arnav::igtl
