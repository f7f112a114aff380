# cmake --install BUILD --prefix P: headers under P/include/odomcov/, the static libraries, the
# CLI, and the CMake package P/lib/cmake/odomcov (find_package(odomcov CONFIG) ->
# odomcov::odomcov, odomcov::closed_form, odomcov::core, odomcov::io).
include(CMakePackageConfigHelpers)
set(ODOMCOV_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/odomcov)

install(DIRECTORY ${PROJECT_SOURCE_DIR}/include/odomcov DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}
        FILES_MATCHING PATTERN "*.hpp")
install(TARGETS odomcov_closed_form odomcov_core odomcov_io odomcov_odomcov
        EXPORT odomcovTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(TARGETS odomcov RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(EXPORT odomcovTargets NAMESPACE odomcov:: DESTINATION ${ODOMCOV_CMAKE_DIR})

configure_package_config_file(${CMAKE_CURRENT_LIST_DIR}/odomcovConfig.cmake.in
                              ${CMAKE_CURRENT_BINARY_DIR}/odomcovConfig.cmake
                              INSTALL_DESTINATION ${ODOMCOV_CMAKE_DIR})
write_basic_package_version_file(${CMAKE_CURRENT_BINARY_DIR}/odomcovConfigVersion.cmake
                                 VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${CMAKE_CURRENT_BINARY_DIR}/odomcovConfig.cmake
              ${CMAKE_CURRENT_BINARY_DIR}/odomcovConfigVersion.cmake
        DESTINATION ${ODOMCOV_CMAKE_DIR})
