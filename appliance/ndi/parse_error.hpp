#pragma once
// Outcome of parsing device bytes. Parsers never throw on bad input and never allocate
// on the BX path; they report what was wrong so the caller can count it.
#include <cstdint>
#include <string_view>

namespace arnav::ndi {

enum class ParseError : std::uint8_t {
  None,
  TooShort,        // fewer bytes than the smallest valid reply
  BadCrc,          // ASCII reply CRC or BX body CRC mismatch
  BadHeader,       // BX start bytes wrong or header CRC mismatch
  LengthMismatch,  // BX length field disagrees with the bytes given
  BadField,        // a fixed-width field has a non-digit or an impossible value
  BadStatus,       // unknown per-handle status byte/word
  TooManyHandles,  // count above kMaxHandles
  TrailingBytes,   // bytes left over after the last field
  WrongKind,       // e.g. an ERROR reply where data was expected
};

std::string_view to_string(ParseError e);

}  // namespace arnav::ndi
