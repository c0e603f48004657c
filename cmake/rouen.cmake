# rouen_library(NAME DIRS dir... PUBLIC deps... PRIVATE deps...)
# One library per folder: every *.cc under DIRS except *_test.cc; the *_test.cc files beside
# the code become one GoogleTest binary NAME_test run by CTest (SHARED_SETUP suites: see
# rouen_discover_tests).
function(rouen_library name)
  cmake_parse_arguments(ARG "" "" "DIRS;PUBLIC;PRIVATE;TEST_DEPS;SHARED_SETUP" ${ARGN})
  set(sources)
  set(tests)
  foreach(dir ${ARG_DIRS})
    file(GLOB found CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/${dir}/*.cc)
    foreach(f ${found})
      if(f MATCHES "_test\\.cc$")
        list(APPEND tests ${f})
      else()
        list(APPEND sources ${f})
      endif()
    endforeach()
  endforeach()
  if(NOT sources)
    message(FATAL_ERROR "${CMAKE_CURRENT_SOURCE_DIR}: no sources for ${name}")
  endif()
  add_library(${name} ${sources})
  target_include_directories(${name} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(${name} PUBLIC ${ARG_PUBLIC} PRIVATE ${ARG_PRIVATE})
  rouen_precompile(${name} rouen_core)
  if(ROUEN_BUILD_TESTS AND tests)
    add_executable(${name}_test ${tests})
    target_link_libraries(${name}_test PRIVATE ${name} ${ARG_TEST_DEPS} GTest::gtest GTest::gmock GTest::gtest_main)
    target_compile_definitions(${name}_test PRIVATE
      ROUEN_SHARED_DIR="${PROJECT_SOURCE_DIR}/../shared"
      ROUEN_SOURCE_DIR="${PROJECT_SOURCE_DIR}")
    rouen_test_code(${name}_test)
    rouen_precompile(${name}_test rouen_core_test <gtest/gtest.h>)
    rouen_discover_tests(${name}_test LABEL unit SHARED_SETUP ${ARG_SHARED_SETUP})
  endif()
endfunction()

# rouen_discover_tests(TARGET LABEL label [SHARED_SETUP suite[=seconds]...])
# One CTest entry per GoogleTest test of TARGET, except the SHARED_SETUP suites: each of those
# is one entry running all its tests in one process, so that a costly SetUpTestSuite (a
# session captured, scenes solved) runs once rather than once per test. `=seconds`, about what
# the suite takes, is its COST (`ctest -j` starts the costliest first) and a third of its
# TIMEOUT. Without it, a fresh checkout (no timings of an earlier run) started them in the order
# of their numbers, the longest last, with the other core idle while it ran.
function(rouen_discover_tests target)
  cmake_parse_arguments(ARG "" "LABEL" "SHARED_SETUP" ${ARGN})
  set(filter "")
  foreach(entry ${ARG_SHARED_SETUP})
    string(REGEX REPLACE "=.*$" "" suite "${entry}")
    string(APPEND filter ":${suite}.*")
  endforeach()
  if(filter)
    string(SUBSTRING "${filter}" 1 -1 filter)
    gtest_discover_tests(${target} DISCOVERY_TIMEOUT 60 TEST_FILTER "-${filter}"
                         PROPERTIES LABELS ${ARG_LABEL})
  else()
    gtest_discover_tests(${target} DISCOVERY_TIMEOUT 60 PROPERTIES LABELS ${ARG_LABEL})
  endif()
  foreach(entry ${ARG_SHARED_SETUP})
    string(REGEX REPLACE "=.*$" "" suite "${entry}")
    add_test(NAME ${suite} COMMAND ${target} --gtest_filter=${suite}.*)
    set_tests_properties(${suite} PROPERTIES LABELS ${ARG_LABEL})
    if(entry MATCHES "=([0-9]+)$")
      # Three times that for its timeout (at least the default): a slower machine still passes,
      # a hang still fails.
      math(EXPR timeout "${CMAKE_MATCH_1} * 3")
      if(timeout LESS 600)
        set(timeout 600)
      endif()
      set_tests_properties(${suite} PROPERTIES COST ${CMAKE_MATCH_1} TIMEOUT ${timeout})
    endif()
  endforeach()
endfunction()

# rouen_test_code(TARGET)
# A test binary's own code at -O1: the work a test measures runs in the libraries, built with
# the build type's optimisation; its own code (GoogleTest's macros, JSON, the checks) is light,
# and at -O3 it was half of a clean build's compile time.
function(rouen_test_code target)
  if(NOT ROUEN_SANITIZE AND CMAKE_BUILD_TYPE MATCHES "^(Release|RelWithDebInfo)$")
    target_compile_options(${target} PRIVATE -O1)
  endif()
endfunction()

# rouen_precompile(TARGET FROM [header...])
# The standard, Eigen and JSON headers most of rouen's files include, parsed once rather than
# once per file: they were most of a clean build's compile time (CLI11 alone is 7 s of every
# command's file). FROM makes them precompiled, with the given headers; every other TARGET
# reuses FROM's (the libraries rouen_core's, the tests rouen_core_test's, which add GoogleTest).
function(rouen_precompile target from)
  if(target STREQUAL from)
    target_precompile_headers(${target} PRIVATE <algorithm> <array> <cmath> <filesystem>
      <functional> <map> <memory> <optional> <string> <vector> <Eigen/Core> <Eigen/Geometry>
      <nlohmann/json.hpp> ${ARGN})
  else()
    target_precompile_headers(${target} REUSE_FROM ${from})
  endif()
endfunction()
