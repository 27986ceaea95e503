#pragma once
// Test helper: the real Polaris session recorded by IGSTK (../shared/data/ndi_captures).
#include <filesystem>
#include <vector>

#include "appliance/ndi/transcript.hpp"

namespace arnav::ndi::test {

std::filesystem::path shared_dir();
std::vector<TranscriptRecord> load_capture();  // polaris_classic_stream.txt as records

}  // namespace arnav::ndi::test
