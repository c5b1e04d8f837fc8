#include "alloc_counter.h"

#include <cstddef>

extern "C" {
void* __libc_malloc(size_t size);
void* __libc_calloc(size_t count, size_t size);
void* __libc_realloc(void* ptr, size_t size);
void* __libc_memalign(size_t alignment, size_t size);
}

namespace {
thread_local bool t_counting = false;  // zero-initialised TLS of the executable: no allocation
thread_local uint64_t t_count = 0;
bool g_seen = false;  // some allocation went through us

inline void note() {
  g_seen = true;
  if (t_counting) ++t_count;
}
}  // namespace

extern "C" {
void* malloc(size_t size) {
  note();
  return __libc_malloc(size);
}
void* calloc(size_t count, size_t size) {
  note();
  return __libc_calloc(count, size);
}
void* realloc(void* ptr, size_t size) {
  note();
  return __libc_realloc(ptr, size);
}
void* memalign(size_t alignment, size_t size) {
  note();
  return __libc_memalign(alignment, size);
}
void* aligned_alloc(size_t alignment, size_t size) {
  note();
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, size_t alignment, size_t size) {
  note();
  void* p = __libc_memalign(alignment, size);
  if (p == nullptr) return 12;  // ENOMEM
  *out = p;
  return 0;
}
}

void alloc_count_begin() {
  t_count = 0;
  t_counting = true;
}

uint64_t alloc_count_end() {
  t_counting = false;
  return t_count;
}

bool alloc_counter_active() { return g_seen; }
