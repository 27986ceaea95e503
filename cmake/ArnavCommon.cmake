# Shared build settings: warnings, sanitizers, dependency targets, test helper.
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(Threads REQUIRED)
find_package(GTest REQUIRED)
find_package(yaml-cpp REQUIRED)
find_package(nlohmann_json REQUIRED)
find_package(CLI11 REQUIRED)

add_library(arnav_warnings INTERFACE)
target_compile_options(arnav_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor -Wcast-align
  -Wunused -Woverloaded-virtual -Wnull-dereference -Wdouble-promotion -Wformat=2
  -Wimplicit-fallthrough)

if(ARNAV_SANITIZE)
  add_compile_options(-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  add_link_options(-fsanitize=address,undefined)
  # Line tables are all that ASan/UBSan reports need (file:line per frame, inlined frames
  # included); full -g (RelWithDebInfo) described every type and variable as well, which
  # cost compile and link time for nothing the sanitizer prints (docs/machine-notes.md,
  # "Build time"). ARNAV_SANITIZE_FULL_DEBUG_INFO=ON keeps full -g for a debugger session.
  option(ARNAV_SANITIZE_FULL_DEBUG_INFO "Sanitizer build: full -g instead of line tables only" OFF)
  if(NOT ARNAV_SANITIZE_FULL_DEBUG_INFO)
    if(CMAKE_CXX_COMPILER_ID MATCHES "Clang")
      add_compile_options(-gline-tables-only)  # after the build type's -g: the last one wins
    else()
      add_compile_options(-g1)
    endif()
  endif()
endif()

# Linker: ld.lld links the ~150 test programs in a fraction of GNU ld's time (docs/
# machine-notes.md, "Build time"). Used when the compiler accepts -fuse-ld=lld; otherwise
# the default linker, with a message. ARNAV_USE_LLD=OFF forces the default.
option(ARNAV_USE_LLD "Link with ld.lld when the compiler can use it" ON)
if(ARNAV_USE_LLD)
  include(CheckLinkerFlag)
  check_linker_flag(CXX -fuse-ld=lld ARNAV_HAVE_LLD)
  if(ARNAV_HAVE_LLD)
    add_link_options(-fuse-ld=lld)
    message(STATUS "ARNAV: linking with ld.lld")
  else()
    message(STATUS "ARNAV: ld.lld not usable with ${CMAKE_CXX_COMPILER} (-fuse-ld=lld failed): default linker")
  endif()
endif()

if(ARNAV_FUZZ AND NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
  message(FATAL_ERROR "ARNAV_FUZZ=ON needs clang (libFuzzer): configure with CXX=clang++")
endif()

# ctest -j starts the longest tests first (their COST; later runs use measured times), so a
# cold CI run does not start a 4-minute test last beside an idle core.
set(ARNAV_SLOW_TESTS sim_patient_meshes_test hil_ar_demo_e2e_test cut_ring_session_test host_replay_test
    hil_ar_phantom_e2e_test register_nonrigid_test hil_phantom_record_test cut_models_test hil_e2e_can_test)

# Every gtest program links this: all tests skipped -> exit 77 (SKIP_RETURN_CODE below).
add_library(arnav_gtest_skip_exit_code OBJECT ${CMAKE_CURRENT_LIST_DIR}/../protocol/testing/skip_exit_code.cpp)
target_link_libraries(arnav_gtest_skip_exit_code PRIVATE GTest::gtest)

# arnav_add_test(NAME name SOURCES a.cpp b.cpp LIBS lib... [LABELS l...])
# One gtest executable registered with ctest; tests live beside the code they test.
function(arnav_add_test)
  cmake_parse_arguments(T "" "NAME;TIMEOUT" "SOURCES;LIBS;LABELS" ${ARGN})
  add_executable(${T_NAME} ${T_SOURCES})
  target_link_libraries(${T_NAME} PRIVATE ${T_LIBS} arnav_gtest_skip_exit_code GTest::gtest GTest::gtest_main arnav_warnings)
  add_test(NAME ${T_NAME} COMMAND ${T_NAME})
  if(NOT T_TIMEOUT)
    set(T_TIMEOUT 300)
  endif()
  # A program whose tests were all skipped exits 77: ctest reports it "Skipped", not "Passed"
  # (protocol/testing/skip_exit_code.cpp; scripts/test lists them).
  set_tests_properties(${T_NAME} PROPERTIES TIMEOUT ${T_TIMEOUT} SKIP_RETURN_CODE 77
    ENVIRONMENT "ARNAV_SOURCE_DIR=${PROJECT_SOURCE_DIR};ARNAV_DATA_DIR=${PROJECT_SOURCE_DIR}/data;ARNAV_BINARY_DIR=${PROJECT_BINARY_DIR}")
  if(T_NAME IN_LIST ARNAV_SLOW_TESTS)
    set_tests_properties(${T_NAME} PROPERTIES COST 1000)
  endif()
  if(T_NAME IN_LIST ARNAV_SANITIZE_TESTS)
    list(APPEND T_LABELS sanitize)  # run in the sanitizer build (root CMakeLists.txt)
  endif()
  if(T_LABELS)
    set_tests_properties(${T_NAME} PROPERTIES LABELS "${T_LABELS}")
  endif()
  arnav_note_test_target(${T_NAME} "${T_LABELS}")
  set_property(GLOBAL APPEND PROPERTY ARNAV_GTEST_TARGETS ${T_NAME})  # precompiled header (ArnavPch.cmake)
endfunction()

# ARNAV_BUILD_TEST_LABELS (a ctest -L regular expression, e.g. the sanitizer build's
# "appliance|hil|fuzz|sanitize"): target arnav_label_tests builds the programs of the tests
# with a matching label, and through their dependencies whatever those tests run; the
# sanitizer build builds only that (scripts/build asan), not the benchmarks and the tests
# it never runs. Empty: arnav_label_tests builds every test.
set(ARNAV_BUILD_TEST_LABELS "" CACHE STRING "ctest -L regex: arnav_label_tests builds the programs of these tests")
function(arnav_note_test_target target labels)
  set(match FALSE)
  if(ARNAV_BUILD_TEST_LABELS STREQUAL "")
    set(match TRUE)
  endif()
  foreach(label ${labels})
    if(label MATCHES "${ARNAV_BUILD_TEST_LABELS}")
      set(match TRUE)
    endif()
  endforeach()
  if(match)
    set_property(GLOBAL APPEND PROPERTY ARNAV_LABEL_TEST_TARGETS ${target})
  endif()
endfunction()

# arnav_add_fuzzer(NAME name SOURCES a.cpp LIBS ... [SEEDS dir])
# libFuzzer target plus a short smoke run in ctest (label "fuzz"): 10 s from the seeds; longer
# campaigns by hand (docs/appliance.md, "libFuzzer targets").
function(arnav_add_fuzzer)
  cmake_parse_arguments(F "" "NAME;SEEDS" "SOURCES;LIBS" ${ARGN})
  if(NOT ARNAV_FUZZ)
    return()
  endif()
  add_executable(${F_NAME} ${F_SOURCES})
  target_compile_options(${F_NAME} PRIVATE -fsanitize=fuzzer)
  target_link_options(${F_NAME} PRIVATE -fsanitize=fuzzer)
  target_link_libraries(${F_NAME} PRIVATE ${F_LIBS})
  set(corpus ${CMAKE_CURRENT_BINARY_DIR}/${F_NAME}_corpus)
  # Fixed seed: a CI failure reproduces with the same command; longer runs by hand vary it.
  set(args -seed=1 -max_total_time=10 -rss_limit_mb=2048 ${corpus})
  if(F_SEEDS)
    list(APPEND args ${F_SEEDS})
  endif()
  # The corpus folder is made fresh in the build tree; seeds are read-only inputs.
  add_test(NAME ${F_NAME}_smoke
    COMMAND sh -c "mkdir -p '${corpus}' && exec \"$0\" \"$@\"" $<TARGET_FILE:${F_NAME}> ${args})
  set_tests_properties(${F_NAME}_smoke PROPERTIES LABELS "fuzz" TIMEOUT 120)
  arnav_note_test_target(${F_NAME} fuzz)
endfunction()
