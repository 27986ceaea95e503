#include "appliance/ndi/rom.hpp"

#include <fstream>

namespace arnav::ndi {

std::string rom_problem(const std::vector<std::uint8_t>& bytes) {
  if (bytes.empty()) return "file is empty";
  if (bytes.size() > kMaxRomBytes) return "file is larger than " + std::to_string(kMaxRomBytes) + " bytes";
  if (bytes.size() < 4 || bytes[0] != 'N' || bytes[1] != 'D' || bytes[2] != 'I' || bytes[3] != 0)
    return "not an NDI tool definition (.rom) file: it does not start with the bytes 'NDI\\0'";
  return {};
}

ToolRom load_rom(const std::filesystem::path& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec))
    throw RomError(path.string() + ": tool definition file not found (or not a regular file)");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw RomError(path.string() + ": cannot open tool definition file");
  ToolRom rom;
  rom.path = path;
  in.seekg(0, std::ios::end);
  const auto size = static_cast<std::size_t>(in.tellg());
  if (size > kMaxRomBytes)
    throw RomError(path.string() + ": file is larger than " + std::to_string(kMaxRomBytes) + " bytes");
  in.seekg(0);
  rom.bytes.resize(size);
  if (!in.read(reinterpret_cast<char*>(rom.bytes.data()), static_cast<std::streamsize>(size)))
    throw RomError(path.string() + ": read error");
  if (auto problem = rom_problem(rom.bytes); !problem.empty()) throw RomError(path.string() + ": " + problem);
  return rom;
}

}  // namespace arnav::ndi
