/* Bit-exact C99 reproduction of numpy.random.default_rng(seed).random().
 * See numpy_random.h. Follows NumPy's numpy/random/bit_generator.pyx
 * (SeedSequence), numpy/random/_pcg64.pyx and src/pcg64/pcg64.[ch] (PCG64),
 * and src/distributions (next_double). */
#include "numpy_random.h"

#if !defined(__SIZEOF_INT128__)
#error "numpy_random.c needs unsigned __int128 (gcc or clang on a 64-bit target)"
#endif

__extension__ typedef unsigned __int128 np_u128;

/* ---- SeedSequence (bit_generator.pyx) ---------------------------------- */

#define NP_SS_POOL_SIZE 4u          /* DEFAULT_POOL_SIZE */
#define NP_SS_INIT_A 0x43b0d7e5u
#define NP_SS_MULT_A 0x931e8875u
#define NP_SS_INIT_B 0x8b51f9ddu
#define NP_SS_MULT_B 0x58f38dedu
#define NP_SS_MIX_MULT_L 0xca01f9ddu
#define NP_SS_MIX_MULT_R 0x4973f715u
#define NP_SS_XSHIFT 16u            /* uint32 bits / 2 */

static uint32_t ss_hashmix(uint32_t value, uint32_t *hash_const)
{
    value ^= *hash_const;
    *hash_const *= NP_SS_MULT_A;
    value *= *hash_const;
    value ^= value >> NP_SS_XSHIFT;
    return value;
}

static uint32_t ss_mix(uint32_t x, uint32_t y)
{
    uint32_t result = NP_SS_MIX_MULT_L * x - NP_SS_MIX_MULT_R * y;
    result ^= result >> NP_SS_XSHIFT;
    return result;
}

/* SeedSequence(seed).generate_state(4, np.uint64) for 0 <= seed < 2**64. */
static void ss_generate_state_u64x4(uint64_t seed, uint64_t out[4])
{
    /* _coerce_to_uint32_array(seed): little-endian uint32 words, i.e. [lo]
     * or [lo, hi] (0 -> [0]). The pool is longer than that, and mix_entropy
     * fills the missing entries with hashmix(0), exactly as if they were
     * zero words, so padding with zeros to the pool size is equivalent. No
     * spawn key, and never more entropy words than the pool size. */
    uint32_t entropy[NP_SS_POOL_SIZE] = {0u, 0u, 0u, 0u};
    uint32_t pool[NP_SS_POOL_SIZE];
    uint32_t words[8];
    uint32_t hash_const = NP_SS_INIT_A;
    unsigned i, i_src, i_dst;

    entropy[0] = (uint32_t)(seed & 0xFFFFFFFFu);
    entropy[1] = (uint32_t)(seed >> 32);

    /* mix_entropy */
    for (i = 0; i < NP_SS_POOL_SIZE; ++i)
        pool[i] = ss_hashmix(entropy[i], &hash_const);
    for (i_src = 0; i_src < NP_SS_POOL_SIZE; ++i_src)
        for (i_dst = 0; i_dst < NP_SS_POOL_SIZE; ++i_dst)
            if (i_src != i_dst)
                pool[i_dst] = ss_mix(pool[i_dst], ss_hashmix(pool[i_src], &hash_const));

    /* generate_state: 4 uint64 = 8 uint32 words, cycling over the pool */
    hash_const = NP_SS_INIT_B;
    for (i = 0; i < 8u; ++i) {
        uint32_t v = pool[i % NP_SS_POOL_SIZE];
        v ^= hash_const;
        hash_const *= NP_SS_MULT_B;
        v *= hash_const;
        v ^= v >> NP_SS_XSHIFT;
        words[i] = v;
    }
    /* viewed as little-endian uint64 */
    for (i = 0; i < 4u; ++i)
        out[i] = (uint64_t)words[2u * i] | ((uint64_t)words[2u * i + 1u] << 32);
}

/* ---- PCG64 = PCG XSL RR 128/64 (src/pcg64/pcg64.h) ----------------------- */

/* PCG_DEFAULT_MULTIPLIER_128 */
#define NP_PCG_MULT_HI 2549297995355413924ULL
#define NP_PCG_MULT_LO 4865540595714422341ULL

static np_u128 u128_make(uint64_t hi, uint64_t lo)
{
    return ((np_u128)hi << 64) | (np_u128)lo;
}

static np_u128 pcg_step(np_u128 state, np_u128 inc)
{
    return state * u128_make(NP_PCG_MULT_HI, NP_PCG_MULT_LO) + inc;
}

static void pcg_store(NpPcg64 *rng, np_u128 state, np_u128 inc)
{
    rng->state_hi = (uint64_t)(state >> 64);
    rng->state_lo = (uint64_t)state;
    rng->inc_hi = (uint64_t)(inc >> 64);
    rng->inc_lo = (uint64_t)inc;
}

void np_default_rng(NpPcg64 *rng, uint64_t seed)
{
    uint64_t w[4];
    np_u128 initstate, initseq, state, inc;

    ss_generate_state_u64x4(seed, w);
    /* pcg64_set_seed(state, seed = &w[0], inc = &w[2]) */
    initstate = u128_make(w[0], w[1]);
    initseq = u128_make(w[2], w[3]);
    /* pcg_setseq_128_srandom_r */
    inc = (initseq << 1) | 1u;
    state = pcg_step(0u, inc);
    state += initstate;
    state = pcg_step(state, inc);
    pcg_store(rng, state, inc);
}

uint64_t np_next_uint64(NpPcg64 *rng)
{
    np_u128 inc = u128_make(rng->inc_hi, rng->inc_lo);
    np_u128 state = pcg_step(u128_make(rng->state_hi, rng->state_lo), inc);
    uint64_t hi = (uint64_t)(state >> 64);
    uint64_t x = hi ^ (uint64_t)state;
    unsigned rot = (unsigned)(hi >> 58);   /* state >> 122 */

    rng->state_hi = hi;
    rng->state_lo = (uint64_t)state;
    return (x >> rot) | (x << ((-rot) & 63u));
}

double np_random(NpPcg64 *rng)
{
    /* next_double / random_standard_uniform */
    return (double)(np_next_uint64(rng) >> 11) * (1.0 / 9007199254740992.0);
}
