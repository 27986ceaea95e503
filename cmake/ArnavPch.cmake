# Precompiled headers (docs/machine-notes.md, "Build time"). Included at the end of the
# root CMakeLists.txt, once every target exists:
#   arnav_pch_test  gtest, Eigen, nlohmann/json and the usual standard headers; every gtest
#                   program (arnav_add_test) reuses its one PCH (REUSE_FROM).
#   arnav_pch_cli   CLI11 (+ json): every other program that links CLI11::CLI11 directly.
# A PCH is used only where the compile flags match those it was built with; GCC checks
# that and falls back to the plain headers (-Winvalid-pch says so in the build log), so a
# mismatch costs time, never correctness. GCC only: clang rejects, with an error, a PCH
# whose language options differ (e.g. -fsanitize=fuzzer), and the sanitizer build (clang)
# builds few command-line programs. With a compiler launcher (ccache) the PCH is off by
# default: ccache skips caching compiles that use one unless configured for it.
set(arnav_pch_default OFF)
if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU" AND NOT CMAKE_CXX_COMPILER_LAUNCHER)
  set(arnav_pch_default ON)
endif()
option(ARNAV_PCH "Precompiled headers for tests and command-line programs (GCC)" ${arnav_pch_default})
if(ARNAV_PCH AND NOT CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
  message(STATUS "ARNAV: ARNAV_PCH needs GCC; ${CMAKE_CXX_COMPILER_ID} builds without precompiled headers")
  set(ARNAV_PCH OFF)
endif()

# All targets defined in dir and below.
function(arnav_targets_below dir out)
  get_property(targets DIRECTORY ${dir} PROPERTY BUILDSYSTEM_TARGETS)
  get_property(subdirs DIRECTORY ${dir} PROPERTY SUBDIRECTORIES)
  foreach(sub ${subdirs})
    arnav_targets_below(${sub} sub_targets)
    list(APPEND targets ${sub_targets})
  endforeach()
  set(${out} ${targets} PARENT_SCOPE)
endfunction()

if(ARNAV_PCH)
  message(STATUS "ARNAV: precompiled headers for tests and command-line programs")
  # The PCH carries the flags of its anchor target: those of a test (arnav_add_test) and
  # of a program linking arnav_warnings.
  add_library(arnav_pch_test OBJECT ${CMAKE_CURRENT_LIST_DIR}/pch/anchor.cpp)
  target_link_libraries(arnav_pch_test PRIVATE GTest::gtest Eigen3::Eigen nlohmann_json::nlohmann_json arnav_warnings)
  target_precompile_headers(arnav_pch_test PRIVATE ${CMAKE_CURRENT_LIST_DIR}/pch/test.hpp)
  add_library(arnav_pch_cli OBJECT ${CMAKE_CURRENT_LIST_DIR}/pch/anchor.cpp)
  target_link_libraries(arnav_pch_cli PRIVATE CLI11::CLI11 nlohmann_json::nlohmann_json arnav_warnings)
  target_precompile_headers(arnav_pch_cli PRIVATE ${CMAKE_CURRENT_LIST_DIR}/pch/cli.hpp)

  get_property(gtest_targets GLOBAL PROPERTY ARNAV_GTEST_TARGETS)
  foreach(t ${gtest_targets})
    target_precompile_headers(${t} REUSE_FROM arnav_pch_test)
  endforeach()
  arnav_targets_below(${PROJECT_SOURCE_DIR} all_targets)
  foreach(t ${all_targets})
    get_target_property(type ${t} TYPE)
    get_target_property(libs ${t} LINK_LIBRARIES)
    get_target_property(options ${t} COMPILE_OPTIONS)
    if(type STREQUAL "EXECUTABLE" AND NOT t IN_LIST gtest_targets AND "CLI11::CLI11" IN_LIST libs
       AND NOT "-fsanitize=fuzzer" IN_LIST options)
      target_precompile_headers(${t} REUSE_FROM arnav_pch_cli)
    endif()
  endforeach()
endif()
