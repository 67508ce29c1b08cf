# SPDX-License-Identifier: Apache-2.0
# What `cmake --install` and the packages put where (docs/install.md).
#
# Files whose text names installed paths (the unit's ExecStart, the
# configurations' /etc/cpmd, tmpfiles.d) are rendered at
# install time by cmake/install-rendered.cmake, for the prefix installed into
# (`cmake --install build --prefix /usr`, CPack's /usr), not the one the build
# was configured with: a build configured for /usr/local packages correctly.

# The daemon's configurations and the models they name: /etc/cpmd, conffiles
# in the package. sil.yaml and machine-sil.yaml are the SIL tests' own.
set(CPMD_CONFIG_FILES cpmd.yaml sim.yaml sim-homing.yaml canopen.yaml machine.yaml machine-canopen.yaml)
set(CPMD_SYSTEMD_UNITDIR "" CACHE PATH
    "Folder for cpmd.service (empty: /lib/systemd/system for prefix /usr, PREFIX/lib/systemd/system otherwise)")

install(CODE "
set(CPMD_SOURCE_DIR [[${PROJECT_SOURCE_DIR}]])
set(CPMD_RENDER_DIR [[${PROJECT_BINARY_DIR}/install-rendered]])
set(CPMD_BINDIR [[${CMAKE_INSTALL_BINDIR}]])
set(CPMD_SYSCONFDIR [[${CMAKE_INSTALL_SYSCONFDIR}]])
set(CPMD_DOCDIR [[${CMAKE_INSTALL_DOCDIR}]])
set(CPMD_UNITDIR [[${CPMD_SYSTEMD_UNITDIR}]])
set(CPMD_CONFIG_FILES [[${CPMD_CONFIG_FILES}]])
include([[${PROJECT_SOURCE_DIR}/cmake/install-rendered.cmake]])
" COMPONENT cpmd)

# systemd creates the user (sysusers.d); PREFIX/lib/sysusers.d is on its path
# for /usr and /usr/local alike.
install(FILES packaging/sysusers.d/cpmd.conf DESTINATION lib/sysusers.d)

# Docs (Debian policy: /usr/share/doc/PACKAGE, with its copyright file). README
# and docs/ keep their relative places, so the links between them resolve.
install(FILES README.md packaging/copyright DESTINATION ${CMAKE_INSTALL_DOCDIR})
install(DIRECTORY docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR}/docs FILES_MATCHING PATTERN "*.md")

# Package cpmd-dev: its own copyright, the example client, the CMake package
# (find_package(cpmd): cpmd::client, cpmd::msgs; cmake/cpmdConfig.cmake.in).
set(CPMD_DEV_DOCDIR ${CMAKE_INSTALL_DATAROOTDIR}/doc/cpmd-dev)
install(FILES packaging/copyright DESTINATION ${CPMD_DEV_DOCDIR} COMPONENT dev)
install(DIRECTORY examples/client DESTINATION ${CPMD_DEV_DOCDIR}/examples COMPONENT dev)

include(CMakePackageConfigHelpers)
set(CPMD_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/cpmd)
install(EXPORT cpmdTargets NAMESPACE cpmd:: DESTINATION ${CPMD_CMAKEDIR} COMPONENT dev)
configure_package_config_file(cmake/cpmdConfig.cmake.in ${PROJECT_BINARY_DIR}/cmake/cpmdConfig.cmake
                              INSTALL_DESTINATION ${CPMD_CMAKEDIR})
# 0.x: a minor version may change the API.
write_basic_package_version_file(${PROJECT_BINARY_DIR}/cmake/cpmdConfigVersion.cmake
                                 VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/cmake/cpmdConfig.cmake ${PROJECT_BINARY_DIR}/cmake/cpmdConfigVersion.cmake
        DESTINATION ${CPMD_CMAKEDIR} COMPONENT dev)
