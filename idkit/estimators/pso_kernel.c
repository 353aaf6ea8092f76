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

   Layout: a swarm's particles are evaluated together, particle index innermost
   (alpha[NB][K], e[NM][K]), so the loops over particles vectorise. */

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
void idkit_uniform(Stream *stream, int64_t count, float *out) {
    int64_t i = 0;
    if (count > 0 && stream->has_uint32) {
        out[i++] = float_of((uint32_t)stream->uinteger);
        stream->has_uint32 = 0;
    }
    uint64_t bits = 0;
    for (; i < count; i += 2) {
        bits = sfc64_next(stream->s);
        out[i] = float_of((uint32_t)bits);
        if (i + 1 < count) out[i + 1] = float_of((uint32_t)(bits >> 32));
        else stream->has_uint32 = 1; /* an odd count: the upper half waits */
        stream->uinteger = bits >> 32;
    }
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

/* One thread's working memory, sized for K particles and a trial's random numbers. */
typedef struct {
    double *alpha, *e, *work, *cost, *value, *moved;
    float *random;
} Scratch;

/* ---- Norms of e[NM][K] for every particle at once: out[K] ---- */

/* Largest singular value of a 3 x N matrix from its Gram matrix g: Smith's closed form for the
   top eigenvalue of a symmetric 3 x 3 matrix (as idkit.estimators.objective.spectral_norm_3). */
static double spectral3(double g00, double g11, double g22, double g01, double g02, double g12) {
    double q = (g00 + g11 + g22) / 3;
    double x = g00 - q, y = g11 - q, z = g22 - q;
    double off = g01 * g01 + g02 * g02 + g12 * g12;
    double p = sqrt((x * x + y * y + z * z + 2 * off) / 6);
    if (!(p > 0)) return sqrt(q > 0 ? q : 0);
    double det = x * (y * z - g12 * g12) - g01 * (g01 * z - g12 * g02) + g02 * (g01 * g12 - y * g02);
    double r = det / (2 * p * p * p);
    r = r < -1 ? -1 : (r > 1 ? 1 : r);
    double top = q + 2 * p * cos(acos(r) / 3);
    return sqrt(top > 0 ? top : 0);
}

/* Sum of the `keep` smallest of the NM values sq[NM][K] of each particle: bubble the largest
   (or, when fewer are kept than dropped, the smallest) to the end, as many times as needed. */
static void trimmed_sum(double *sq, int64_t K, int64_t keep, double *out) {
    int64_t drop = NM - keep;
    int largest = drop <= keep;
    int64_t passes = largest ? drop : keep;
    for (int64_t pass = 0; pass < passes; pass++)
        for (int64_t m = 0; m + 1 < NM - pass; m++) {
            double *a = sq + m * K, *b = a + K;
            for (int64_t k = 0; k < K; k++) {
                double lo = a[k] < b[k] ? a[k] : b[k], hi = a[k] < b[k] ? b[k] : a[k];
                a[k] = largest ? lo : hi;
                b[k] = largest ? hi : lo;
            }
        }
    /* largest: the kept values are the first `keep`; else the last `keep` (smallest bubbled there) */
    int64_t first = largest ? 0 : NM - keep;
    for (int64_t k = 0; k < K; k++) out[k] = 0;
    for (int64_t m = first; m < first + keep; m++)
        for (int64_t k = 0; k < K; k++) out[k] += sq[m * K + k];
}

static void norm_values(int32_t code, double param, const double *e, int64_t K, double *work, double *out) {
    for (int64_t k = 0; k < K; k++) out[k] = 0;
    switch (code) {
    case 1: /* Frobenius */
        for (int64_t m = 0; m < NM; m++)
            for (int64_t k = 0; k < K; k++) out[k] += e[m * K + k] * e[m * K + k];
        for (int64_t k = 0; k < K; k++) out[k] = sqrt(out[k]);
        return;
    case 2: { /* spectral (NJ == 3): Gram matrix of the rows, then the closed form */
        double *g = work; /* [6][K]: g00, g11, g22, g01, g02, g12 */
        static const int rows[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {0, 2}, {1, 2}};
        for (int c = 0; c < 6; c++) {
            const double *a = e + rows[c][0] * NS * K, *b = e + rows[c][1] * NS * K;
            double *gc = g + c * K;
            for (int64_t k = 0; k < K; k++) gc[k] = 0;
            for (int64_t j = 0; j < NS; j++)
                for (int64_t k = 0; k < K; k++) gc[k] += a[j * K + k] * b[j * K + k];
        }
        for (int64_t k = 0; k < K; k++)
            out[k] = spectral3(g[k], g[K + k], g[2 * K + k], g[3 * K + k], g[4 * K + k], g[5 * K + k]);
        return;
    }
    case 3: /* largest column (sample) absolute sum */
        for (int64_t j = 0; j < NS; j++) {
            double *col = work;
            for (int64_t k = 0; k < K; k++) col[k] = 0;
            for (int64_t i = 0; i < NJ; i++)
                for (int64_t k = 0; k < K; k++) col[k] += fabs(e[(i * NS + j) * K + k]);
            for (int64_t k = 0; k < K; k++) out[k] = col[k] > out[k] ? col[k] : out[k];
        }
        return;
    case 4: /* largest row (joint) absolute sum */
    case 5: /* largest row square sum */
        for (int64_t i = 0; i < NJ; i++) {
            double *row = work;
            for (int64_t k = 0; k < K; k++) row[k] = 0;
            for (int64_t j = 0; j < NS; j++)
                for (int64_t k = 0; k < K; k++) {
                    double a = e[(i * NS + j) * K + k];
                    row[k] += code == 4 ? fabs(a) : a * a;
                }
            for (int64_t k = 0; k < K; k++) out[k] = row[k] > out[k] ? row[k] : out[k];
        }
        return;
    case 6: /* largest absolute entry */
        for (int64_t m = 0; m < NM; m++)
            for (int64_t k = 0; k < K; k++) {
                double a = fabs(e[m * K + k]);
                out[k] = a > out[k] ? a : out[k];
            }
        return;
    case 7: /* mean Huber loss, threshold param */
        for (int64_t m = 0; m < NM; m++)
            for (int64_t k = 0; k < K; k++) {
                double a = fabs(e[m * K + k]);
                out[k] += a <= param ? 0.5 * (a * a) : param * (a - 0.5 * param);
            }
        for (int64_t k = 0; k < K; k++) out[k] = out[k] / NM;
        return;
    case 8: { /* mean of the smallest squares, the fraction param of the largest left out */
        int64_t keep = NM - (int64_t)floor(param * NM + 1e-9);
        double *sq = work; /* [NM][K] */
        for (int64_t m = 0; m < NM * K; m++) sq[m] = e[m] * e[m];
        trimmed_sum(sq, K, keep, out);
        for (int64_t k = 0; k < K; k++) out[k] = out[k] / keep;
        return;
    }
    }
    for (int64_t k = 0; k < K; k++) out[k] = NAN;
}

/* ---- One swarm: evaluate, update bests, move ---- */

/* Cost of every particle of swarm s into w->cost, then personal bests and the swarm's best
   (its cost into *best). */
static void evaluate(const Batch *b, int64_t s, Scratch *w, double *best) {
    const int64_t K = b->K, slot = b->slot_of[s];
    const double *x = b->x + s * K * NP;
    double *alpha = w->alpha, *e = w->e, *cost = w->cost;
    for (int64_t k = 0; k < K; k++) {
        double a[NB];
#if USE_MAP
        base_map(x + k * NP, a);
#else
        memcpy(a, b->alpha + (s * K + k) * NB, sizeof a);
#endif
        for (int bb = 0; bb < NB; bb++) alpha[bb * K + k] = a[bb];
    }
    /* E = T/d - alpha . Y^T/d, added up in the order of the eager engine's baddbmm */
    const double *linear = b->linear + slot * NB * NM, *offset = b->offset + slot * NM;
    for (int64_t m = 0; m < NM; m++) {
        double *row = e + m * K;
        for (int64_t k = 0; k < K; k++) row[k] = offset[m] + alpha[k] * linear[m];
        for (int bb = 1; bb < NB; bb++) {
            const double c = linear[bb * NM + m], *ab = alpha + bb * K;
            for (int64_t k = 0; k < K; k++) row[k] += ab[k] * c;
        }
    }
    const int32_t *codes = b->codes + slot * MAX_NORMS;
    const double *params = b->params + slot * MAX_NORMS;
    for (int64_t k = 0; k < K; k++) cost[k] = 1;
    for (int c = 0; c < MAX_NORMS && codes[c]; c++) {
        norm_values(codes[c], params[c], e, K, w->work, w->value);
        for (int64_t k = 0; k < K; k++) cost[k] *= w->value[k];
    }
    double *pcost = b->pcost + s * K, *pbest = b->pbest + s * K * NP;
    for (int64_t k = 0; k < K; k++)
        if (cost[k] < pcost[k]) { /* strictly better; NaN never is */
            pcost[k] = cost[k];
            for (int p = 0; p < NP; p++) pbest[k * NP + p] = x[k * NP + p];
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

/* Move swarm s with inertia `weight` and its uniform numbers r1, r2 (and u3 for the random
   wall rule), each [K][NP] (or [K] per particle), then apply the boundary rule. */
static void move(const Batch *b, int64_t s, double weight, const float *r1, const float *r2, const float *u3,
                 double *moved) {
    const int64_t K = b->K;
    const int64_t rk = b->per_particle ? 1 : NP, rp = b->per_particle ? 0 : 1; /* strides into r */
    double *x = b->x + s * K * NP, *v = b->v + s * K * NP;
    const double *pbest = b->pbest + s * K * NP, *g = b->gpos + s * NP;
    const double *lower = b->lower, *upper = b->upper;
    double vmax[NP];
    for (int p = 0; p < NP; p++) vmax[p] = b->velocity_limit > 0 ? b->velocity_limit * (upper[p] - lower[p]) : INFINITY;
    for (int64_t k = 0; k < K; k++)
        for (int p = 0; p < NP; p++) {
            int64_t i = k * NP + p, ri = k * rk + p * rp;
            double xi = x[i];
            double vel = v[i] * weight + ((double)r1[ri] * b->c1) * (pbest[i] - xi);
            vel = vel + ((double)r2[ri] * b->c2) * (g[p] - xi);
            vel = vel < -vmax[p] ? -vmax[p] : (vel > vmax[p] ? vmax[p] : vel);
            v[i] = vel;
            moved[i] = xi + vel;
        }
    switch (b->boundary) {
    case CLAMP:
        for (int64_t k = 0; k < K; k++)
            for (int p = 0; p < NP; p++) {
                int64_t i = k * NP + p;
                double pos = moved[i], c = pos < lower[p] ? lower[p] : (pos > upper[p] ? upper[p] : pos);
                v[i] = c != pos ? 0 : v[i];
                x[i] = c;
            }
        return;
    case REFLECT:
        for (int64_t k = 0; k < K; k++)
            for (int p = 0; p < NP; p++) {
                int64_t i = k * NP + p;
                double width = upper[p] - lower[p];
                double t = moved[i] - lower[p]; /* fmod(t, 2 width) is t itself inside [0, 2 width) */
                double folded = width - (t >= 0 && t < 2 * width ? t : remainder_(t, 2 * width));
                x[i] = upper[p] - fabs(folded);
                v[i] = folded > 0 ? v[i] : (folded < 0 ? -v[i] : 0 * v[i]);
            }
        return;
    default: /* RANDOM: between the previous position and the wall it crossed */
        for (int64_t k = 0; k < K; k++)
            for (int p = 0; p < NP; p++) {
                int64_t i = k * NP + p;
                double pos = moved[i], xi = x[i], u = (double)u3[k * rk + p * rp];
                int out_low = pos < lower[p], out_high = pos > upper[p];
                if (out_low) pos = lower[p] + (xi - lower[p]) * u;
                if (out_high) pos = upper[p] - (upper[p] - xi) * u;
                if (out_low || out_high) v[i] = 0;
                x[i] = pos;
            }
    }
}

/* ---- Runs: trials [t0, t1), `moves` moves each, then `last` final evaluation ---- */

static int64_t draws_of(const Batch *b) { return b->boundary == RANDOM ? 3 : 2; }

/* Evaluation m writes each swarm's best cost to history[m][S]; move m uses weights[m] and the
   trial's next draws x (S/T) x K x (NP, or 1 per particle) uniform numbers, drawn r1 first, then
   r2, then u3, each swarm-major, as the eager engine's blocks. Trials are independent, so any
   split of them over threads gives the same numbers. */
static int64_t run_trials(const Batch *b, int64_t t0, int64_t t1, double *history, int64_t moves,
                          const double *weights, int64_t last) {
    const int64_t K = b->K, per = b->S / b->T, width = b->per_particle ? 1 : NP;
    const int64_t draws = draws_of(b), block = per * K * width;
    int64_t work = NM * K > 6 * K ? NM * K : 6 * K;
    Scratch w;
    double *memory = malloc(sizeof(double) * (size_t)(NB * K + NM * K + work + 2 * K + K * NP));
    w.random = malloc(sizeof(float) * (size_t)(draws * block));
    if (!memory || !w.random) {
        free(memory);
        free(w.random);
        return -1;
    }
    w.alpha = memory;
    w.e = w.alpha + NB * K;
    w.work = w.e + NM * K;
    w.cost = w.work + work;
    w.value = w.cost + K;
    w.moved = w.value + K;
    for (int64_t t = t0; t < t1; t++) {
        for (int64_t m = 0; m < moves + last; m++) {
            int moving = m < moves;
            if (moving) idkit_uniform(b->streams + t, draws * block, w.random);
            for (int64_t s = t * per; s < (t + 1) * per; s++) {
                evaluate(b, s, &w, history + m * b->S + s);
                if (!moving) continue;
                const float *r = w.random + (s - t * per) * K * width;
                move(b, s, weights[m], r, r + block, draws > 2 ? r + 2 * block : NULL, w.moved);
            }
        }
    }
    free(memory);
    free(w.random);
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
