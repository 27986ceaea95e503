#pragma once
// Test helper: the real Polaris session recorded by IGSTK (data/ndi_captures, see data/README.md).
#include <filesystem>
#include <vector>

#include "appliance/ndi/transcript.hpp"

namespace arnav::ndi::test {

std::filesystem::path data_dir();
std::vector<TranscriptRecord> load_capture();  // polaris_classic_stream.txt as records

}  // namespace arnav::ndi::test
