# Cross-compiling for the robot boards (aarch64) on a Debian 12 x86-64 host:
#   toolchain/setup-host --cross
#   cmake -S . -B build-aarch64 -DCMAKE_TOOLCHAIN_FILE=toolchain/aarch64-linux-gnu.cmake
#   cmake --build build-aarch64 -j && ctest --test-dir build-aarch64   # tests run under qemu-aarch64
# Debian's multiarch layout means no sysroot: the arm64 -dev packages install
# beside the host's, and CMAKE_LIBRARY_ARCHITECTURE points the searches at them.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR aarch64)
set(CMAKE_C_COMPILER aarch64-linux-gnu-gcc)
set(CMAKE_CXX_COMPILER aarch64-linux-gnu-g++)
set(CMAKE_LIBRARY_ARCHITECTURE aarch64-linux-gnu)
find_program(FOVEA_CROSS_PKG_CONFIG aarch64-linux-gnu-pkg-config)
if(FOVEA_CROSS_PKG_CONFIG)
  set(PKG_CONFIG_EXECUTABLE ${FOVEA_CROSS_PKG_CONFIG} CACHE FILEPATH "")
endif()
# ctest runs the test binaries through user-mode emulation.
set(CMAKE_CROSSCOMPILING_EMULATOR qemu-aarch64 CACHE STRING "")
