# SPDX-License-Identifier: Apache-2.0
# cpm_add_sil_test(NAME <name> [NEEDS can|gpio|can,gpio] [TIMEOUT <s>] [HOST <cmd> [args...]]
#                  COMMAND <cmd> [args...])
#
# Registers a CTest test that runs <cmd> through tests/sil/run-in-vm.sh:
# on the host in a fresh network namespace when it has vcan (and gpio-sim if
# NEEDS gpio), otherwise in Debian's kernel under QEMU. Labelled "sil". The
# first run downloads and builds the VM image (test sil.prepare, a fixture
# every SIL test requires, so that the download is not charged to a test's
# own time-out). TIMEOUT (default 300 s) bounds the run itself, boot included.
# HOST: a command on the host that runs the runner's command line (its last
# arguments) and works beside the guest, e.g. through a shared folder.
# Include this file from a tests/<module>/CMakeLists.txt:
#   include(${PROJECT_SOURCE_DIR}/tests/sil/SilTest.cmake)
include_guard(GLOBAL)

# Global, not directory-scoped: the function is called from several folders.
set_property(GLOBAL PROPERTY CPM_SIL_RUNNER ${CMAKE_CURRENT_LIST_DIR}/run-in-vm.sh)
option(CPM_SIL_TESTS "Register the SIL tests (vcan/gpio-sim; boot a VM when the host has neither)" ON)

function(cpm_add_sil_test)
  cmake_parse_arguments(ARG "" "NAME;NEEDS;TIMEOUT" "COMMAND;HOST" ${ARGN})
  if(NOT CPM_SIL_TESTS)
    return()
  endif()
  if(NOT ARG_NAME OR NOT ARG_COMMAND)
    message(FATAL_ERROR "cpm_add_sil_test: NAME and COMMAND are required")
  endif()
  if(NOT ARG_NEEDS)
    set(ARG_NEEDS can,gpio)
  endif()
  if(NOT ARG_TIMEOUT)
    set(ARG_TIMEOUT 300)
  endif()
  get_property(CPM_SIL_RUNNER GLOBAL PROPERTY CPM_SIL_RUNNER)
  # One sil.prepare for the whole project (`if(TEST ...)` sees only this folder).
  get_property(prepared GLOBAL PROPERTY CPM_SIL_PREPARE_ADDED)
  if(NOT prepared)
    add_test(NAME sil.prepare COMMAND bash ${CPM_SIL_RUNNER} --prepare --needs can,gpio)
    set_tests_properties(sil.prepare PROPERTIES LABELS sil TIMEOUT 1200 FIXTURES_SETUP cpm_sil_image)
    set_property(GLOBAL PROPERTY CPM_SIL_PREPARE_ADDED TRUE)
  endif()
  # The guest has its own /tmp and /run: a tree under them is shared in.
  set(share "")
  foreach(dir ${PROJECT_SOURCE_DIR} ${CMAKE_BINARY_DIR})
    if(dir MATCHES "^/(tmp|run)/")
      list(APPEND share --rw ${dir})
    endif()
  endforeach()
  add_test(NAME ${ARG_NAME}
           COMMAND ${ARG_HOST} bash ${CPM_SIL_RUNNER} --needs ${ARG_NEEDS} --timeout ${ARG_TIMEOUT} ${share} -- ${ARG_COMMAND}
           WORKING_DIRECTORY ${CMAKE_BINARY_DIR})
  # CTest's own limit sits above the runner's, so that the runner reports
  # the time-out (with the serial log) rather than being killed.
  math(EXPR ctest_timeout "${ARG_TIMEOUT} + 60")
  set_tests_properties(${ARG_NAME} PROPERTIES LABELS sil TIMEOUT ${ctest_timeout}
                       FIXTURES_REQUIRED cpm_sil_image)
endfunction()
