// The object the test binaries' precompiled header is built with
// (tests/CMakeLists.txt: fovea_test_pch); nothing links it.
int fovea_test_pch_anchor = 0;
