# Cross-compiling odomcov for 64-bit ARM (Jetson, Raspberry Pi 4/5) with Debian's cross compiler,
# running the tests under qemu-user. Used by scripts/cross_aarch64.sh, which fills the sysroot
# with Debian's arm64 packages (extracted, not installed, so the host's amd64 packages stay).
#   ODOMCOV_AARCH64_SYSROOT: the folder the arm64 .deb files were extracted into.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)

if(NOT ODOMCOV_AARCH64_SYSROOT)
  set(ODOMCOV_AARCH64_SYSROOT $ENV{ODOMCOV_AARCH64_SYSROOT})
endif()
set(_sysroot ${ODOMCOV_AARCH64_SYSROOT})
set(_arch_lib ${_sysroot}/usr/lib/aarch64-linux-gnu)

# Libraries come from the sysroot's arm64 packages; header-only packages (Eigen, Boost, CLI11,
# nlohmann-json, Random123) are architecture-independent and come from the host through a folder
# of links, so the host's /usr/include (with its amd64 C library) never enters a compile line.
set(CMAKE_FIND_ROOT_PATH ${_sysroot} /usr/aarch64-linux-gnu)
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE BOTH)
set(TBB_DIR ${_arch_lib}/cmake/TBB CACHE PATH "")
set(yaml-cpp_DIR ${_arch_lib}/cmake/yaml-cpp CACHE PATH "")
set(NLopt_DIR ${_arch_lib}/cmake/nlopt CACHE PATH "")
set(GTest_DIR ${_arch_lib}/cmake/GTest CACHE PATH "")
set(hwy_DIR ${_arch_lib}/cmake/hwy CACHE PATH "")
set(benchmark_DIR ${_arch_lib}/cmake/benchmark CACHE PATH "")
set(Eigen3_DIR /usr/share/eigen3/cmake CACHE PATH "")
set(CLI11_DIR /usr/share/cmake/CLI11 CACHE PATH "")
set(nlohmann_json_DIR /usr/share/cmake/nlohmann_json CACHE PATH "")
set(Boost_NO_BOOST_CMAKE ON CACHE BOOL "")
set(Boost_INCLUDE_DIR ${_sysroot}/host-headers CACHE PATH "")
set(RANDOM123_INCLUDE_DIR ${_sysroot}/host-headers CACHE PATH "")

set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64;-L;/usr/aarch64-linux-gnu;-E;LD_LIBRARY_PATH=${_arch_lib})
set(CMAKE_BUILD_RPATH ${_arch_lib})
