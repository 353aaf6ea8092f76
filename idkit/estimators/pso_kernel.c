/* The native PSO engine's kernel: whole PSO runs of a batch of swarms, random numbers included.

   idkit.estimators.native compiles this file with a generated prefix that fixes the sizes, so
   that the loops over them unroll and vectorise:
     NJ, NS      the error matrix E is NJ x NS (joints x samples), stored as NM = NJ * NS entries;
     NB, NP      base parameters and search dimensions;
     MAX_NORMS   most norms one cost multiplies;
     USE_MAP     1: base_map(x[NP], alpha[NB]), defined in the prefix, maps positions to base
                 parameters; 0: the caller gives the base parameters (Batch.alpha) every move.
   The arithmetic is IEEE (no fast-math, no FMA contraction) and follows the eager engine's
   operations in order, so both engines agree to rounding.

   Layout: particles are evaluated LANES at a time, one per lane of a vector (below); a move is a
   few flat loops over the swarm's K x NP coordinates. Both vectorise. */

#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define NM (NJ * NS)
#define MAX_THREADS 64

enum { CLAMP = 0, REFLECT = 1, RANDOM = 2 };

/* ---- Random numbers: numpy's SFC64 bit generator and Generator.random(dtype=float32) ---- */

/* numpy's SFC64 state (bit_generator.state): s[4], and the upper half of the last 64-bit draw
   when only its lower half was used (has_uint32, uinteger), both widened to 64 bits. */
typedef struct {
    uint64_t s[4];
    uint64_t has_uint32, uinteger;
} Stream;

static inline uint64_t sfc64_next(uint64_t *s) {
    const uint64_t out = s[0] + s[1] + s[3]++;
    s[0] = s[1] ^ (s[1] >> 11);
    s[1] = s[2] + (s[2] << 3);
    s[2] = ((s[2] << 24) | (s[2] >> 40)) + out;
    return out;
}

/* numpy's next_float: the top 24 bits of a 32-bit draw, times 2^-24 (exact in float). */
static inline float float_of(uint32_t bits) { return (float)(bits >> 8) * (1.0f / 16777216.0f); }

/* `count` numbers of Generator.random(count, dtype=float32): one 32-bit draw each, the lower half
   of a 64-bit draw first, its upper half kept for the next number. numpy stores every upper half
   in uinteger, used or not: so does this, and the whole state matches numpy's. */
void idkit_uniform(Stream *stream, int64_t count, float *restrict out) {
    uint64_t s[4] = {stream->s[0], stream->s[1], stream->s[2], stream->s[3]}, upper = stream->uinteger;
    int64_t i = 0;
    if (count > 0 && stream->has_uint32) {
        out[i++] = float_of((uint32_t)upper);
        stream->has_uint32 = 0;
    }
    for (; i + 2 <= count; i += 2) {
        const uint64_t bits = sfc64_next(s);
        out[i] = float_of((uint32_t)bits);
        out[i + 1] = float_of((uint32_t)(bits >> 32));
        upper = bits >> 32;
    }
    if (i < count) { /* an odd count: the upper half waits for the next number */
        const uint64_t bits = sfc64_next(s);
        out[i] = float_of((uint32_t)bits);
        upper = bits >> 32;
        stream->has_uint32 = 1;
    }
    memcpy(stream->s, s, sizeof s);
    stream->uinteger = upper;
}

/* ---- The batch ---- */

/* S swarms of K particles: trial t owns swarms [t S/T, (t+1) S/T) and draws from streams[t].
   linear[L, NB, NM] (-Y^T / d), offset[L, NM] (T / d), slot_of[S] in [0, L), codes[L, MAX_NORMS]
   (0 = none), params[L, MAX_NORMS]; state x, v, pbest [S, K, NP], pcost [S, K], gpos [S, NP]. */
typedef struct {
    int64_t S, T, K;
    const double *linear, *offset;
    const int64_t *slot_of;
    const int32_t *codes;
    const double *params;
    double *x, *v, *pbest, *pcost, *gpos;
    const double *lower, *upper;
    double c1, c2, velocity_limit; /* velocity_limit <= 0: none */
    int64_t boundary, per_particle;
    Stream *streams;
    const double *alpha; /* [S, K, NB]: the base parameters of x, read when USE_MAP is 0 */
} Batch;

/* ---- Norms of a group of LANES particles at once: e[NM] -> one value per lane ---- */

/* Particles are evaluated LANES at a time, one per lane of a vector (GCC/Clang vector
   extensions: one AVX2 register of doubles; plain SSE or scalar code elsewhere), so the error
   matrix and its norms are vector arithmetic with compile-time loop bounds. */
#define LANES 4
/* Error matrices up to this many entries live on the stack (32 kB of lanes): the compiler then
   knows that nothing else points into them. Larger ones (long recordings) use the heap. */
#define STACK_NM 1024
typedef double Lanes __attribute__((vector_size(LANES * sizeof(double))));
typedef int64_t LaneMask __attribute__((vector_size(LANES * sizeof(double))));

/* mask ? a : b, lane by lane (C has no vector ?:) */
static inline Lanes pick(LaneMask mask, Lanes a, Lanes b) {
    return (Lanes)((mask & (LaneMask)a) | (~mask & (LaneMask)b));
}
static inline Lanes lanes_abs(Lanes a) { return (Lanes)((LaneMask)a & INT64_MAX); }
/* a > b ? a : b, as the scalar running maximum (a NaN sum never wins) */
static inline Lanes larger(Lanes a, Lanes b) { return pick(a > b, a, b); }
static inline Lanes lanes_sqrt(Lanes a) {
    for (int l = 0; l < LANES; l++) a[l] = sqrt(a[l]);
    return a;
}

static inline Lanes splat(double value) { return (Lanes){0} + value; }

/* acos and cos lane by lane, to a few ulp, for the spectral norm's closed form (libm's are one
   number at a time). Polynomials fitted by mpmath.chebyfit: degree 12 for (asin(s) - s) / s^3 in
   z = s^2 on [0, 1/4], degree 7 for cos(t) in u = t^2 on [0, (pi/3)^2]; highest degree first.
   The tests compare the spectral norm with an SVD (torch.linalg.matrix_norm). */
static const double ASIN_FIT[13] = {
    0.028757851367421566, -0.014851887071247204, 0.01740087944269402,  0.005457506718640358, 0.01032281435018578,
    0.011479177415184906, 0.013971212973552933,  0.017352392720869973, 0.02237217294214989,  0.030381944138531247,
    0.04464285714635543,  0.07499999999998433,   0.16666666666666669};
static const double COS_FIT[8] = {-1.1262869231464423e-11, 2.0873062951942423e-09, -2.755728499304865e-07,
                                  2.480158712576133e-05,   -0.0013888888888398316, 0.04166666666665994,
                                  -0.49999999999999967,    1.0};
#define PI_HI 3.141592653589793
#define PI_LO 1.2246467991473532e-16

/* The polynomial fit[0] z^(terms-1) + ... + fit[terms-1] by Estrin's scheme (pairs, then pairs of
   pairs): a few dependent steps instead of Horner's `terms`, so that its latency does not bound
   the evaluation. */
static inline Lanes polynomial(const double *fit, int terms, Lanes z) {
    Lanes c[16];
    for (int i = 0; i < terms; i++) c[i] = splat(fit[terms - 1 - i]);
    for (int n = terms; n > 1; n = (n + 1) / 2, z = z * z)
        for (int i = 0; 2 * i < n; i++) c[i] = 2 * i + 1 < n ? c[2 * i] + z * c[2 * i + 1] : c[2 * i];
    return c[0];
}

/* asin(s) for |s| <= 1/2 */
static inline Lanes asin_half(Lanes s) {
    const Lanes z = s * s;
    return s + s * (z * polynomial(ASIN_FIT, 13, z));
}

/* acos(r) for r in [-1, 1]: pi/2 - asin(r) in the middle, 2 asin(sqrt((1 - |r|)/2)) (or pi minus
   it) near the ends, where 1 - |r| is exact. */
static inline Lanes lanes_acos(Lanes r) {
    const Lanes a = lanes_abs(r);
    const LaneMask ends = a > 0.5;
    const Lanes angle = asin_half(pick(ends, lanes_sqrt((1 - a) * 0.5), r));
    const Lanes end = pick(r > 0, 2 * angle, PI_HI - (2 * angle - PI_LO));
    return pick(ends, end, (0.5 * PI_HI - angle) + 0.5 * PI_LO);
}

/* Largest singular value of a 3 x N matrix from its Gram matrix g (g00, g11, g22, g01, g02, g12):
   Smith's closed form for the top eigenvalue of a symmetric 3 x 3 matrix, as
   idkit.estimators.objective.spectral_norm_3. */
static Lanes spectral3(const Lanes *g) {
    const Lanes q = (g[0] + g[1] + g[2]) / 3;
    const Lanes x = g[0] - q, y = g[1] - q, z = g[2] - q;
    const Lanes off = g[3] * g[3] + g[4] * g[4] + g[5] * g[5];
    const Lanes p = lanes_sqrt((x * x + y * y + z * z + 2 * off) / 6);
    const LaneMask positive = p > 0;
    const Lanes safe = pick(positive, p, splat(1));
    const Lanes det = x * (y * z - g[5] * g[5]) - g[3] * (g[3] * z - g[5] * g[4]) + g[4] * (g[3] * g[5] - y * g[4]);
    Lanes r = det / (2 * safe * safe * safe);
    r = pick(r < -1, splat(-1), r);
    r = pick(r > 1, splat(1), r);
    const Lanes t = lanes_acos(r) / 3;
    const Lanes top = pick(positive, q + 2 * p * polynomial(COS_FIT, 8, t * t), q);
    return lanes_sqrt(pick(top > 0, top, splat(0)));
}

/* Sum of the `keep` smallest of the NM values sq[NM] of each lane: bubble the largest (or, when
   fewer are kept than dropped, the smallest) to the end, as many times as needed. */
static Lanes trimmed_sum(Lanes *sq, int64_t keep) {
    const int64_t drop = NM - keep;
    const int largest = drop <= keep;
    const int64_t passes = largest ? drop : keep;
    for (int64_t pass = 0; pass < passes; pass++)
        for (int64_t m = 0; m + 1 < NM - pass; m++) {
            const LaneMask less = sq[m] < sq[m + 1];
            const Lanes low = pick(less, sq[m], sq[m + 1]), high = pick(less, sq[m + 1], sq[m]);
            sq[m] = largest ? low : high;
            sq[m + 1] = largest ? high : low;
        }
    /* largest: the kept values are the first `keep`; else the last `keep` (smallest bubbled there) */
    const int64_t first = largest ? 0 : NM - keep;
    Lanes sum = {0};
    for (int64_t m = first; m < first + keep; m++) sum += sq[m];
    return sum;
}

/* The Gram matrix of e's rows (NJ == 3), g00, g11, g22, g01, g02, g12: what the spectral norm's
   closed form (spectral3) needs. */
static void gram3(const Lanes *e, Lanes *g) {
    static const int rows[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {0, 2}, {1, 2}};
    for (int c = 0; c < 6; c++) {
        g[c] = splat(0);
        for (int j = 0; j < NS; j++) g[c] += e[rows[c][0] * NS + j] * e[rows[c][1] * NS + j];
    }
}

/* Every norm but the spectral one (code 2: gram3, then spectral3). */
static Lanes norm_values(int32_t code, double param, const Lanes *restrict e, Lanes *restrict squares) {
    Lanes acc = {0}, sums;
    switch (code) {
    case 1: /* Frobenius */
        for (int m = 0; m < NM; m++) acc += e[m] * e[m];
        return lanes_sqrt(acc);
    case 3: /* largest column (sample) absolute sum */
        for (int j = 0; j < NS; j++) {
            sums = (Lanes){0};
            for (int i = 0; i < NJ; i++) sums += lanes_abs(e[i * NS + j]);
            acc = larger(sums, acc);
        }
        return acc;
    case 4: /* largest row (joint) absolute sum */
        for (int i = 0; i < NJ; i++) {
            sums = (Lanes){0};
            for (int j = 0; j < NS; j++) sums += lanes_abs(e[i * NS + j]);
            acc = larger(sums, acc);
        }
        return acc;
    case 5: /* largest row square sum */
        for (int i = 0; i < NJ; i++) {
            sums = (Lanes){0};
            for (int j = 0; j < NS; j++) sums += e[i * NS + j] * e[i * NS + j];
            acc = larger(sums, acc);
        }
        return acc;
    case 6: /* largest absolute entry */
        for (int m = 0; m < NM; m++) acc = larger(lanes_abs(e[m]), acc);
        return acc;
    case 7: /* mean Huber loss, threshold param */
        for (int m = 0; m < NM; m++) {
            const Lanes a = lanes_abs(e[m]);
            acc += pick(a <= param, 0.5 * (a * a), param * (a - 0.5 * param));
        }
        return acc / NM;
    case 8: { /* mean of the smallest squares, the fraction param of the largest left out */
        const int64_t keep = NM - (int64_t)floor(param * NM + 1e-9);
#if NM <= STACK_NM
        Lanes local[NM];
        squares = local;
#endif
        for (int m = 0; m < NM; m++) squares[m] = e[m] * e[m];
        return trimmed_sum(squares, keep) / (double)keep;
    }
    }
    return acc + NAN;
}

/* ---- One swarm: evaluate, update bests, move ---- */

/* A thread's working memory for evaluations: a group of LANES particles' error matrix e[NM] and
   its squares[NM] (the trimmed norm sorts them) when they are too large for the stack, and per group
   of a swarm each norm's value [MAX_NORMS][groups] and the spectral norm's Gram matrices
   [MAX_NORMS][groups][6]. The spectral norm's closed forms of all groups then run back to back:
   their long dependency chains (square roots, divisions, polynomials) overlap instead of following
   each other. */
typedef struct {
    Lanes *e, *squares, *values, *grams;
} Norms;

/* Cost of every particle of swarm s, then personal bests and the swarm's best (its cost into
   *best, its position into gpos). */
static void evaluate(const Batch *b, int64_t s, const Norms *w, double *best) {
    const int64_t K = b->K, slot = b->slot_of[s], groups = (K + LANES - 1) / LANES;
    const double *restrict x = b->x + s * K * NP;
    const double *restrict linear = b->linear + slot * NB * NM, *restrict offset = b->offset + slot * NM;
    const int32_t *codes = b->codes + slot * MAX_NORMS;
    const double *params = b->params + slot * MAX_NORMS;
    double *restrict pcost = b->pcost + s * K, *restrict pbest = b->pbest + s * K * NP;
    int norms = 0;
    while (norms < MAX_NORMS && codes[norms]) norms++;
    for (int64_t group = 0; group < groups; group++) {
        Lanes alpha[NB];
#if NM <= STACK_NM
        Lanes e[NM];
#else
        Lanes *restrict e = w->e;
#endif
        for (int l = 0; l < LANES; l++) {
            const int64_t k0 = group * LANES + l, k = k0 < K ? k0 : K - 1; /* a partial group repeats one */
            double a[NB];
#if USE_MAP
            base_map(x + k * NP, a);
#else
            memcpy(a, b->alpha + (s * K + k) * NB, sizeof a);
#endif
            for (int i = 0; i < NB; i++) alpha[i][l] = a[i];
        }
        /* E = T/d - alpha . Y^T/d, added up in the order of the eager engine's baddbmm */
        for (int m = 0; m < NM; m++) {
            e[m] = offset[m] + alpha[0] * linear[m];
            for (int i = 1; i < NB; i++) e[m] += alpha[i] * linear[i * NM + m];
        }
        for (int c = 0; c < norms; c++)
            if (codes[c] == 2) gram3(e, w->grams + (c * groups + group) * 6);
            else w->values[c * groups + group] = norm_values(codes[c], params[c], e, w->squares);
    }
    for (int c = 0; c < norms; c++)
        if (codes[c] == 2)
            for (int64_t group = 0; group < groups; group++)
                w->values[c * groups + group] = spectral3(w->grams + (c * groups + group) * 6);
    for (int64_t group = 0; group < groups; group++) {
        Lanes cost = w->values[group]; /* the norms' product, in their order (as the eager engine) */
        for (int c = 1; c < norms; c++) cost *= w->values[c * groups + group];
        for (int l = 0; l < LANES && group * LANES + l < K; l++) {
            const int64_t k = group * LANES + l;
            const int better = cost[l] < pcost[k]; /* strictly; NaN never is. No branch: unpredictable */
            pcost[k] = better ? cost[l] : pcost[k];
            for (int p = 0; p < NP; p++) pbest[k * NP + p] = better ? x[k * NP + p] : pbest[k * NP + p];
        }
    }
    /* the first particle with the smallest personal best (NaN propagates, as torch.min) */
    int64_t arg = 0;
    double low = pcost[0];
    for (int64_t k = 1; k < K; k++) {
        double c = pcost[k];
        if (low != low) break;
        if (c < low || c != c) { low = c; arg = k; }
    }
    *best = low;
    for (int p = 0; p < NP; p++) b->gpos[s * NP + p] = pbest[arg * NP + p];
}

/* Python-style remainder (sign of the divisor), as torch.remainder. */
static double remainder_(double a, double b) {
    double r = fmod(a, b);
    if (r != 0 && ((r < 0) != (b < 0))) r += b;
    return r;
}

/* A thread's working memory for moves: flat arrays of the K x NP coordinates of a swarm, so that
   every loop over coordinates is one flat loop that vectorises. The box is set once. */
typedef struct {
    double *lower, *upper, *width, *vmax; /* the box and the velocity limit per coordinate */
    double *g, *r1, *r2, *u, *moved;      /* the swarm's best, scaled numbers, moved positions */
} Coordinates;

/* The per-coordinate view of one of the swarm's [K][NP] (or [K] per particle) number blocks. */
static void spread(const float *restrict numbers, double scale, int64_t K, int per_particle, double *restrict out) {
    if (per_particle)
        for (int64_t k = 0; k < K; k++)
            for (int p = 0; p < NP; p++) out[k * NP + p] = (double)numbers[k] * scale;
    else
        for (int64_t i = 0; i < K * NP; i++) out[i] = (double)numbers[i] * scale;
}

/* Move swarm s with inertia `weight` and its uniform numbers r1, r2 (and u3 for the random wall
   rule), then apply the boundary rule; as swarm.step, operation by operation. */
static void move(const Batch *b, int64_t s, double weight, const float *r1, const float *r2, const float *u3,
                 const Coordinates *c) {
    const int64_t K = b->K, n = K * NP;
    double *restrict x = b->x + s * n, *restrict v = b->v + s * n;
    const double *restrict pbest = b->pbest + s * n;
    const double *restrict lower = c->lower, *restrict upper = c->upper, *restrict width = c->width;
    const double *restrict vmax = c->vmax;
    double *restrict g = c->g, *restrict c1r1 = c->r1, *restrict c2r2 = c->r2, *restrict moved = c->moved;
    for (int64_t k = 0; k < K; k++)
        for (int p = 0; p < NP; p++) g[k * NP + p] = b->gpos[s * NP + p];
    spread(r1, b->c1, K, (int)b->per_particle, c1r1);
    spread(r2, b->c2, K, (int)b->per_particle, c2r2);
    for (int64_t i = 0; i < n; i++) {
        double vel = v[i] * weight + c1r1[i] * (pbest[i] - x[i]);
        vel = vel + c2r2[i] * (g[i] - x[i]);
        vel = vel < -vmax[i] ? -vmax[i] : vel; /* vmax is infinite without a velocity limit */
        vel = vel > vmax[i] ? vmax[i] : vel;
        v[i] = vel;
        moved[i] = x[i] + vel;
    }
    switch (b->boundary) {
    case CLAMP:
        for (int64_t i = 0; i < n; i++) {
            const double low = moved[i] < lower[i] ? lower[i] : moved[i];
            const double clamped = low > upper[i] ? upper[i] : low;
            v[i] = v[i] * (double)(clamped == moved[i]); /* velocity * (clamped == position) */
            x[i] = clamped;
        }
        return;
    case REFLECT: {
        /* t = (x - lower) mod 2 width (torch.remainder) folded onto the box. The remainder is t
           itself on [0, 2 width) and t + 2 width on [-2 width, 0), exactly as fmod and the sign
           correction give it; farther out (rare) it is computed in full. */
        int far = 0;
        for (int64_t i = 0; i < n; i++) {
            moved[i] = moved[i] - lower[i];
            far |= !(moved[i] >= -2 * width[i] && moved[i] < 2 * width[i]);
        }
        if (far)
            for (int64_t i = 0; i < n; i++)
                if (!(moved[i] >= -2 * width[i] && moved[i] < 2 * width[i]))
                    moved[i] = remainder_(moved[i], 2 * width[i]);
        for (int64_t i = 0; i < n; i++) {
            const double t = moved[i] < 0 ? moved[i] + 2 * width[i] : moved[i];
            const double folded = width[i] - t;
            x[i] = upper[i] - fabs(folded);
            v[i] = v[i] * ((double)(folded > 0) - (double)(folded < 0)); /* velocity * sign(folded) */
        }
        return;
    }
    default: { /* RANDOM: between the previous position and the wall it crossed */
        double *restrict u = c->u;
        spread(u3, 1.0, K, (int)b->per_particle, u);
        for (int64_t i = 0; i < n; i++) {
            const int out_low = moved[i] < lower[i], out_high = moved[i] > upper[i];
            const double low = lower[i] + (x[i] - lower[i]) * u[i], high = upper[i] - (upper[i] - x[i]) * u[i];
            const double pos = out_low ? low : moved[i];
            x[i] = out_high ? high : pos;
            v[i] = out_low | out_high ? 0 : v[i];
        }
    }
    }
}

/* ---- Runs: trials [t0, t1), `moves` moves each, then `last` final evaluation ---- */

/* Evaluation m writes each swarm's best cost to history[m][S]; move m uses weights[m] and the
   trial's next draws x (S/T) x K x (NP, or 1 per particle) uniform numbers, drawn r1 first, then
   r2, then u3, each swarm-major, as the eager engine's blocks. Trials are independent, so any
   split of them over threads gives the same numbers. */
static int64_t run_trials(const Batch *b, int64_t t0, int64_t t1, double *history, int64_t moves,
                          const double *weights, int64_t last) {
    const int64_t K = b->K, per = b->S / b->T, width = b->per_particle ? 1 : NP;
    const int64_t draws = b->boundary == RANDOM ? 3 : 2, block = per * K * width;
    const int64_t groups = (K + LANES - 1) / LANES, n = K * NP;
    double *memory = malloc(sizeof(double) * (size_t)(9 * n));
    float *random = malloc(sizeof(float) * (size_t)(draws * block));
    Lanes *lanes = aligned_alloc(sizeof(Lanes), sizeof(Lanes) * (size_t)(2 * NM + 7 * MAX_NORMS * groups));
    if (!memory || !random || !lanes) {
        free(memory);
        free(random);
        free(lanes);
        return -1;
    }
    const Norms norms = {lanes, lanes + NM, lanes + 2 * NM, lanes + 2 * NM + MAX_NORMS * groups};
    const Coordinates c = {memory,         memory + n,     memory + 2 * n, memory + 3 * n, memory + 4 * n,
                           memory + 5 * n, memory + 6 * n, memory + 7 * n, memory + 8 * n};
    for (int64_t k = 0; k < K; k++)
        for (int p = 0; p < NP; p++) {
            const int64_t i = k * NP + p;
            c.lower[i] = b->lower[p];
            c.upper[i] = b->upper[p];
            c.width[i] = b->upper[p] - b->lower[p];
            c.vmax[i] = b->velocity_limit > 0 ? b->velocity_limit * c.width[i] : INFINITY;
        }
    for (int64_t t = t0; t < t1; t++) {
        for (int64_t m = 0; m < moves + last; m++) {
            const int moving = m < moves;
            if (moving) idkit_uniform(b->streams + t, draws * block, random);
            for (int64_t s = t * per; s < (t + 1) * per; s++) {
                evaluate(b, s, &norms, history + m * b->S + s);
                if (!moving) continue;
                const float *r = random + (s - t * per) * K * width;
                move(b, s, weights[m], r, r + block, draws > 2 ? r + 2 * block : NULL, &c);
            }
        }
    }
    free(memory);
    free(random);
    free(lanes);
    return 0;
}

typedef struct {
    const Batch *batch;
    int64_t t0, t1, moves, last, status;
    double *history;
    const double *weights;
} Part;

static void *run_part(void *arg) {
    Part *p = (Part *)arg;
    p->status = run_trials(p->batch, p->t0, p->t1, p->history, p->moves, p->weights, p->last);
    return NULL;
}

/* `moves` moves of every swarm (each an evaluation, best updates and a move), then, if `last`,
   one more evaluation; history[moves + last][S]. Trials are split over `threads` threads. */
int64_t idkit_pso_run(const Batch *batch, double *history, int64_t moves, const double *weights, int64_t last,
                      int64_t threads) {
    if (threads > MAX_THREADS) threads = MAX_THREADS;
    if (threads > batch->T) threads = batch->T;
    if (threads < 1) threads = 1;
    Part parts[MAX_THREADS];
    pthread_t ids[MAX_THREADS];
    int started[MAX_THREADS] = {0};
    for (int64_t i = 0; i < threads; i++) {
        Part part = {batch, batch->T * i / threads, batch->T * (i + 1) / threads, moves, last, 0, history, weights};
        parts[i] = part;
    }
    for (int64_t i = 1; i < threads; i++) started[i] = pthread_create(&ids[i], NULL, run_part, &parts[i]) == 0;
    run_part(&parts[0]);
    int64_t status = parts[0].status;
    for (int64_t i = 1; i < threads; i++) {
        if (started[i]) pthread_join(ids[i], NULL);
        else run_part(&parts[i]); /* could not start a thread: do its share here */
        if (parts[i].status) status = parts[i].status;
    }
    return status;
}
