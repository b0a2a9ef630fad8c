// Heap-allocation counting for the tests that prove a real-time path never allocates: a test
// binary that compiles tests/support/alloc_counter.cpp has its global allocation functions
// replaced by ones that count every call, from every thread.
#pragma once

namespace agv::test {

// Allocation calls (every operator new form) since the binary started.
long allocations();

}  // namespace agv::test
