# Precompiled headers (docs/machine-notes.md, "Build time"). Included at the end of the
# root CMakeLists.txt, once every target exists:
#   arnav_pch_test  gtest, Eigen, nlohmann/json and the usual standard headers; every gtest
#                   program (arnav_add_test) reuses its one PCH (REUSE_FROM).
# Measured (docs/machine-notes.md): -22 % compile CPU on a sample of test sources. A second
# PCH with CLI11 for the command-line programs saved nothing (its cost is code generation,
# not parsing) and was dropped.
# A PCH is used only where the compile flags match those it was built with; GCC checks
# that and falls back to the plain headers (-Winvalid-pch says so in the build log), so a
# mismatch costs time, never correctness. GCC only: clang rejects, with an error, a PCH
# whose language options differ (e.g. -fsanitize=fuzzer). With a compiler launcher
# (ccache) the PCH is off by default: ccache skips caching compiles that use one unless
# configured for it (sloppiness pch_defines,time_macros).
set(arnav_pch_default OFF)
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" AND NOT CMAKE_CXX_COMPILER_LAUNCHER)
  set(arnav_pch_default ON)
endif()
option(ARNAV_PCH "Precompiled header for the gtest programs (GCC)" ${arnav_pch_default})
if(ARNAV_PCH AND NOT CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
  message(STATUS "ARNAV: ARNAV_PCH needs GCC; ${CMAKE_CXX_COMPILER_ID} builds without precompiled headers")
  set(ARNAV_PCH OFF)
endif()

if(ARNAV_PCH)
  message(STATUS "ARNAV: precompiled header for the gtest programs")
  # The PCH carries the flags of its anchor target: those of a test (arnav_add_test).
  add_library(arnav_pch_test OBJECT ${CMAKE_CURRENT_LIST_DIR}/pch/anchor.cpp)
  target_link_libraries(arnav_pch_test PRIVATE GTest::gtest Eigen3::Eigen nlohmann_json::nlohmann_json arnav_warnings)
  target_precompile_headers(arnav_pch_test PRIVATE ${CMAKE_CURRENT_LIST_DIR}/pch/test.hpp)

  get_property(gtest_targets GLOBAL PROPERTY ARNAV_GTEST_TARGETS)
  foreach(t ${gtest_targets})
    target_precompile_headers(${t} REUSE_FROM arnav_pch_test)
  endforeach()
endif()
