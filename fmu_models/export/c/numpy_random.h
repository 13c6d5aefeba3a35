/* Bit-exact C99 reproduction of NumPy's default random generator.
 *
 *     rng = numpy.random.default_rng(seed)   # seed: int, 0 <= seed < 2**64
 *     rng.random()                           # double in [0, 1)
 *
 * default_rng(seed) is Generator(PCG64(SeedSequence(seed))):
 *   - SeedSequence(seed) hashes the seed (as little-endian uint32 words) into
 *     a 4-word pool, and generate_state(4, uint64) turns the pool into four
 *     uint64 words w[0..3];
 *   - PCG64 seeds its 128-bit LCG with initstate = w[0]<<64 | w[1] and
 *     initseq = w[2]<<64 | w[3] (pcg64_set_seed / pcg_setseq_128_srandom_r);
 *   - PCG64 is PCG XSL RR 128/64 with the standard 128-bit multiplier
 *     (not PCG64DXSM), step-then-output;
 *   - Generator.random() is (next_uint64 >> 11) * 2**-53.
 * The streams agree with NumPy value for value and bit for bit (checked by
 * tests/fmus/test_numpy_random.py).
 *
 * Self-contained: no global state, no allocation, only <stdint.h>. The
 * implementation needs a compiler with unsigned __int128 (gcc/clang on 64-bit
 * targets); this header itself is plain C99.
 */
#ifndef NUMPY_RANDOM_H
#define NUMPY_RANDOM_H

#include <stdint.h>

/* The generator state: plain data, 32 bytes, may be memcpy'd, saved and
 * restored (e.g. inside an FMU state). The four words are, in this order,
 * the high and low halves of PCG64's 128-bit state and increment: exactly
 * numpy's  rng.bit_generator.state['state']['state'] and [...]['inc']
 * (state = state_hi * 2**64 + state_lo, inc = inc_hi * 2**64 + inc_lo). */
typedef struct {
    uint64_t state_hi, state_lo;
    uint64_t inc_hi, inc_lo;
} NpPcg64;

/* rng := numpy.random.default_rng(seed) for a Python int seed in [0, 2**64). */
void np_default_rng(NpPcg64 *rng, uint64_t seed);

/* Next raw 64-bit output: rng.bit_generator.random_raw(). Advances rng. */
uint64_t np_next_uint64(NpPcg64 *rng);

/* Next double in [0, 1): rng.random(). Consumes one np_next_uint64. */
double np_random(NpPcg64 *rng);

#endif /* NUMPY_RANDOM_H */
