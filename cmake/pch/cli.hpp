// Precompiled header of the command-line programs (cmake/ArnavPch.cmake): CLI11 2.1 is
// header-only and takes ~5 s of compile time in each of the ~30 sources that include it.
#pragma once
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>
