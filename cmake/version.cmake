# SPDX-License-Identifier: Apache-2.0
# The build's version, for --version, the package and the CMake package.
# CPM_VERSION: `git describe --tags --dirty` when the source is a git clone
# with git on the path (tag v0.2.0, 14 commits on: 0.2.0-14-g1b1cebc; no
# release tag reachable: 0.2.0+g1b1cebc; uncommitted changes: -dirty or
# .dirty), else the project's version
# (a release tarball). Read at configure time: re-run cmake for a fresh one
# (tools/build.sh does).
set(CPM_VERSION ${PROJECT_VERSION})
find_package(Git QUIET)
if(GIT_FOUND AND EXISTS ${PROJECT_SOURCE_DIR}/.git)
  execute_process(COMMAND ${GIT_EXECUTABLE} describe --tags --dirty --match "v[0-9]*"
                  WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
                  OUTPUT_VARIABLE _cpm_describe OUTPUT_STRIP_TRAILING_WHITESPACE
                  RESULT_VARIABLE _cpm_describe_rc ERROR_QUIET)
  if(_cpm_describe_rc EQUAL 0)
    string(REGEX REPLACE "^v" "" CPM_VERSION "${_cpm_describe}")
  else()
    # No release tag reachable: the project's version with the commit as build metadata.
    execute_process(COMMAND ${GIT_EXECUTABLE} rev-parse --short HEAD WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
                    OUTPUT_VARIABLE _cpm_commit OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE _cpm_rc ERROR_QUIET)
    execute_process(COMMAND ${GIT_EXECUTABLE} diff --quiet HEAD WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
                    RESULT_VARIABLE _cpm_dirty ERROR_QUIET)
    if(_cpm_rc EQUAL 0)
      set(CPM_VERSION "${PROJECT_VERSION}+g${_cpm_commit}")
      if(NOT _cpm_dirty EQUAL 0)
        string(APPEND CPM_VERSION ".dirty")
      endif()
    endif()
  endif()
endif()
message(STATUS "cpmd version ${CPM_VERSION}")

# cpm/version.hpp: cpm::kVersion, for every program's --version.
configure_file(${PROJECT_SOURCE_DIR}/cmake/version.hpp.in ${PROJECT_BINARY_DIR}/generated/include/cpm/version.hpp @ONLY)
add_library(cpm_version INTERFACE)
target_include_directories(cpm_version INTERFACE $<BUILD_INTERFACE:${PROJECT_BINARY_DIR}/generated/include>)
