# SPDX-License-Identifier: Apache-2.0
# Runs at install time (install(CODE) in cmake/install.cmake), with
# CMAKE_INSTALL_PREFIX as installed into: places the files whose text names
# installed paths. /etc follows GNUInstallDirs' rules: prefix /usr -> /etc,
# /opt/NAME -> /etc/opt/NAME, else PREFIX/etc. The state stays in
# /var/lib/cpmd whatever the prefix: it is the unit's StateDirectory=.
# file(INSTALL) adds DESTDIR and records the install manifest.

cmake_policy(VERSION 3.25)  # install scripts run with no policy set: @VAR@ in quotes stays text

function(cpmd_system_dir out rel)
  if(IS_ABSOLUTE "${rel}")
    set(dir "${rel}")
  elseif(CMAKE_INSTALL_PREFIX MATCHES "^/(usr/?)?$")
    set(dir "/${rel}")
  elseif(CMAKE_INSTALL_PREFIX MATCHES "^/opt/(.*)")
    set(dir "/${rel}/opt/${CMAKE_MATCH_1}")
  else()
    set(dir "${CMAKE_INSTALL_PREFIX}/${rel}")
  endif()
  set(${out} "${dir}" PARENT_SCOPE)
endfunction()

function(cpmd_prefix_dir out rel)
  if(IS_ABSOLUTE "${rel}")
    set(${out} "${rel}" PARENT_SCOPE)
  else()
    string(REGEX REPLACE "/$" "" p "${CMAKE_INSTALL_PREFIX}")
    set(${out} "${p}/${rel}" PARENT_SCOPE)
  endif()
endfunction()

cpmd_system_dir(_etc "${CPMD_SYSCONFDIR}")
set(CPMD_CONFDIR "${_etc}/cpmd")
cpmd_prefix_dir(CPMD_BINDIR_FULL "${CPMD_BINDIR}")
cpmd_prefix_dir(CPMD_DOCDIR_FULL "${CPMD_DOCDIR}")
if(CPMD_UNITDIR)
  set(_unitdir "${CPMD_UNITDIR}")
elseif(CMAKE_INSTALL_PREFIX MATCHES "^/usr/?$")
  set(_unitdir "/lib/systemd/system")  # Debian bookworm's place for packaged units
else()
  cpmd_prefix_dir(_unitdir "lib/systemd/system")
endif()

# One folder per destination: two installs may run at once (the tests do).
string(MD5 _where "$ENV{DESTDIR}|${CMAKE_INSTALL_PREFIX}")
set(CPMD_RENDER_DIR "${CPMD_RENDER_DIR}/${_where}")
file(REMOVE_RECURSE "${CPMD_RENDER_DIR}")
foreach(t IN ITEMS systemd/cpmd.service packaging/tmpfiles.d/cpmd.conf)
  file(READ "${CPMD_SOURCE_DIR}/${t}.in" _text)
  string(CONFIGURE "${_text}" _text @ONLY)
  file(WRITE "${CPMD_RENDER_DIR}/${t}" "${_text}")
endforeach()

# The configurations as in config/, with the system's paths in them.
set(_confs)
foreach(f IN LISTS CPMD_CONFIG_FILES)
  file(READ "${CPMD_SOURCE_DIR}/config/${f}" _text)
  string(REPLACE "/etc/cpmd" "@CPMD_CONFDIR@" _text "${_text}")
  string(REPLACE "build/bin/cpmd --config config/" "cpmd --config @CPMD_CONFDIR@/" _text "${_text}")
  string(CONFIGURE "${_text}" _text @ONLY)
  file(WRITE "${CPMD_RENDER_DIR}/config/${f}" "${_text}")
  list(APPEND _confs "${CPMD_RENDER_DIR}/config/${f}")
endforeach()

file(INSTALL DESTINATION "${CPMD_CONFDIR}" TYPE FILE FILES ${_confs})
file(INSTALL DESTINATION "${_unitdir}" TYPE FILE FILES "${CPMD_RENDER_DIR}/systemd/cpmd.service")
cpmd_prefix_dir(_tmpfilesdir "lib/tmpfiles.d")
file(INSTALL DESTINATION "${_tmpfilesdir}" TYPE FILE FILES "${CPMD_RENDER_DIR}/packaging/tmpfiles.d/cpmd.conf")
