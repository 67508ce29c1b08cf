# SPDX-License-Identifier: Apache-2.0
# The Debian packages, built by CPack from the install rules (docs/install.md):
#   cd build && cpack -G DEB       -> cpmd_VERSION-1_ARCH.deb, cpmd-dev_VERSION-1_ARCH.deb
# cpmd: the programs, the unit, /etc/cpmd (conffiles), the .lcm definitions,
# the docs. cpmd-dev: the client library, its headers, the message headers,
# the CMake package and the example client.

# Debian's version from CPM_VERSION (cmake/version.cmake): a '-' would start
# the Debian revision, so git describe's 0.2.0-14-g1b1cebc-dirty becomes
# 0.2.0+14.g1b1cebc.dirty; 0.2.0+g1b1cebc stays as it is.
string(REGEX REPLACE "^([0-9][^-]*)-" "\\1+" CPM_DEBIAN_VERSION "${CPM_VERSION}")
string(REPLACE "-" "." CPM_DEBIAN_VERSION "${CPM_DEBIAN_VERSION}")
if(NOT CPM_DEBIAN_VERSION MATCHES "^[0-9][A-Za-z0-9.+~]*$")
  message(FATAL_ERROR "cpmd version '${CPM_VERSION}' gives no valid Debian version ('${CPM_DEBIAN_VERSION}')")
endif()

set(CPMD_PACKAGE_MAINTAINER "cpmd maintainers <maintainers@users.noreply.h-seed-7464dbb9.example>"
    CACHE STRING "Maintainer field of the Debian packages")

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME cpmd)
set(CPACK_PACKAGE_VERSION "${CPM_DEBIAN_VERSION}")
set(CPACK_PACKAGE_CONTACT "${CPMD_PACKAGE_MAINTAINER}")
# No CPACK_PACKAGE_DESCRIPTION_SUMMARY: each package's description below
# starts with its own synopsis line, which CPack would otherwise precede.
# The files are placed under DESTDIR with prefix /usr: the paths rendered
# into the unit and the configurations are then the system's own.
set(CPACK_SET_DESTDIR ON)
set(CPACK_INSTALL_PREFIX /usr)
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
# Binaries stripped, as dh_strip does (static libraries keep their symbols).
set(CPACK_STRIP_FILES ON)

set(CPACK_DEB_COMPONENT_INSTALL ON)
set(CPACK_COMPONENTS_ALL cpmd dev)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_RELEASE 1)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)

set(CPACK_DEBIAN_CPMD_PACKAGE_NAME cpmd)
set(CPACK_DEBIAN_CPMD_PACKAGE_SECTION misc)
# The libraries cpmd and cpm link, with the versions they need: dpkg-shlibdeps.
set(CPACK_DEBIAN_CPMD_PACKAGE_SHLIBDEPS ON)
# postinst makes the user with systemd-sysusers, else adduser. procps: the
# unit's ExecReload is /bin/kill, which a minimal Debian lacks (a reload under
# systemd failed there with "Command /bin/kill is not executable").
set(CPACK_DEBIAN_CPMD_PACKAGE_DEPENDS "systemd | adduser, procps")
set(CPACK_DEBIAN_CPMD_PACKAGE_SUGGESTS "can-utils, gpiod")
set(CPACK_COMPONENT_CPMD_DESCRIPTION
    "motion controller for the 3-PRRR Cartesian parallel manipulator
cpmd is a real-time motion controller daemon: it takes trajectories over LCM,
applies calibrated inverse kinematics and computed-torque control, and drives
three CiA 402 servo drives over SocketCAN with e-stop, limits and brake on GPIO,
or a simulator of the machine. cpm is its command line: daemon client,
calibration from ball-bar or position measurements, and diagnosis of the model
against measured motion.")

# conffiles: every configuration in /etc/cpmd (cmake/install.cmake), so that
# dpkg keeps the administrator's changes on upgrade.
set(_conffiles "")
foreach(f IN LISTS CPMD_CONFIG_FILES)
  string(APPEND _conffiles "/etc/cpmd/${f}\n")
endforeach()
file(WRITE ${PROJECT_BINARY_DIR}/packaging/conffiles "${_conffiles}")
set(CPACK_DEBIAN_CPMD_PACKAGE_CONTROL_EXTRA
    ${PROJECT_BINARY_DIR}/packaging/conffiles
    ${PROJECT_SOURCE_DIR}/packaging/debian/postinst
    ${PROJECT_SOURCE_DIR}/packaging/debian/prerm
    ${PROJECT_SOURCE_DIR}/packaging/debian/postrm)
set(CPACK_DEBIAN_CPMD_PACKAGE_CONTROL_STRICT_PERMISSION ON)

set(CPACK_DEBIAN_DEV_PACKAGE_NAME cpmd-dev)
set(CPACK_DEBIAN_DEV_PACKAGE_SECTION libdevel)
# What a program built with find_package(cpmd) compiles and links against.
set(CPACK_DEBIAN_DEV_PACKAGE_DEPENDS "liblcm-dev, libyaml-cpp-dev, libssl-dev, libsodium-dev")
set(CPACK_DEBIAN_DEV_PACKAGE_RECOMMENDS "cmake")
set(CPACK_DEBIAN_DEV_PACKAGE_SUGGESTS "cpmd")
set(CPACK_COMPONENT_DEV_DESCRIPTION
    "client library and message types of cpmd
The static client library of cpmd (talk to a running cpmd over LCM, commands
signed with an operator's key), the C++ headers of its LCM messages, a CMake
package (find_package(cpmd): cpmd::client, cpmd::msgs) and an example client.")

include(CPack)
