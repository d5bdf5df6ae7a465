// Per-pixel kernels compiled twice, for x86-64-v3 (AVX2) and for the baseline, the copy picked
// at load time by the CPU (GCC function multi-versioning): the build stays portable and a
// modern CPU runs 8 floats per instruction instead of 4. Put it on loop-level functions (each
// call goes through the resolver). Files using it are compiled with -ffp-contract=off, so both
// copies give bit-identical results (no FMA contraction in one and not in the other).
#pragma once

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define OBJDB_VECTOR_CLONES __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define OBJDB_VECTOR_CLONES
#endif

// A row kernel called from an OBJDB_VECTOR_CLONES function: always inlined, so that it is
// compiled into each copy for that copy's instruction set (a call would run the baseline).
#if defined(__GNUC__)
#define OBJDB_INLINE_KERNEL inline __attribute__((always_inline))
#else
#define OBJDB_INLINE_KERNEL inline
#endif
