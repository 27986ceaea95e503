// libFuzzer target: arbitrary bytes from a client, cut into chunks of sizes the input also
// chooses, through igtl::StreamReader and the version-2 content bounds. Every outcome must
// be messages or an error, never a crash, an overread or an allocation above the limits.
#include <cstddef>
#include <cstdint>
#include <span>

#include "host/igtl/wire.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  const std::size_t chunk = 1 + data[0] % 97;
  std::span<const std::uint8_t> rest(data + 1, size - 1);
  arnav::igtl::StreamReader reader({"STT_TDATA", "STP_TDATA", "GET_STATUS", "GET_POLYDATA", "STATUS"}, 4096, 1u << 20);
  while (!rest.empty()) {
    const std::size_t n = rest.size() < chunk ? rest.size() : chunk;
    reader.feed(rest.first(n));
    rest = rest.subspan(n);
    while (auto m = reader.next()) {
      if (m->body_kept && m->body.size() != m->header.body_size) __builtin_trap();
      std::string why;
      if (auto content = arnav::igtl::body_content(m->header, m->body, why))
        if (content->size() > m->body.size()) __builtin_trap();
      (void)arnav::igtl::body_crc(m->body);
    }
  }
  return 0;
}
