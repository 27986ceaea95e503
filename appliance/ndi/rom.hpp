#pragma once
// NDI passive tool definition (.rom) files. They are checked before any serial traffic:
// a file that is missing, empty, too large or does not begin with "NDI\0" is refused
// with an error that names the file.
#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace arnav::ndi {

class RomError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ToolRom {
  std::filesystem::path path;
  std::vector<std::uint8_t> bytes;
  // Number of 64-byte PVWR chunks sent: the file zero padded to a multiple of 1024 bytes,
  // as real hosts do (16 chunks for a 752-byte ROM).
  std::size_t chunk_count() const { return (bytes.size() + 1023) / 1024 * 16; }
};

// Largest definition file accepted (real files are 752 bytes; PVWR addresses are 16 bit).
inline constexpr std::size_t kMaxRomBytes = 64 * 1024;

// Checks the bytes of a tool definition; returns an empty string when acceptable, else
// the reason (e.g. "does not start with the NDI signature").
std::string rom_problem(const std::vector<std::uint8_t>& bytes);

// Reads and checks; throws RomError("<path>: <reason>") on any problem.
ToolRom load_rom(const std::filesystem::path& path);

}  // namespace arnav::ndi
