// Counts heap allocations made by the calling thread between begin and end, by interposing
// malloc and its siblings in the test driver (glibc: the program's definitions win over libc's
// and forward to __libc_*). operator new goes through malloc, so C++ allocations count too.
// For sdk_check only: it checks that the game-thread calls allocate nothing.
#ifndef CAMDIRECTOR_ALLOC_COUNTER_H
#define CAMDIRECTOR_ALLOC_COUNTER_H

#include <cstdint>

void alloc_count_begin();
uint64_t alloc_count_end();  // allocations by this thread since alloc_count_begin
bool alloc_counter_active(); // false where the interposition did not take (then counts are 0)

#endif
