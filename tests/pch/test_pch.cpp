// The owner of the test programs' shared precompiled header (tests/CMakeLists.txt, AGV_TESTS_PCH):
// CMake compiles the header list given there for this object library, and every test program
// reuses it. Nothing else belongs here.
