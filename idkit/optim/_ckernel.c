/* Candidate (b) of the fast kernel: the same loops as idkit/optim/kernel.py, in portable C, built
   into a CPython extension when the package is built (setuptools ext_modules), so nothing is
   compiled at run time. Random numbers come from the trial's numpy bit generator through its
   documented C interface (numpy/random/bitgen.h: bitgen_t, reached from the bit generator's
   "BitGenerator" capsule): next_double, as Generator.random calls it.

   run_trial(rng, first, count, weights, last, history, x, v, pbest, pcost, gpos, linear, offset,
             slot_of, codes, params, joints, lower, upper, constants, flags, tape,
             tape_constants, outputs, given) -- the arguments of kernel.run_trial, in order. */

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "numpy/random/bitgen.h"

enum { FRO = 1, SPECTRAL, COLUMN_SUM, ROW_SUM, ROW_SQUARES, MAX_ABS, HUBER, TRIMMED };
enum { CLAMP = 0, REFLECT, RANDOM };
enum { MAP_IDENTITY = 0, MAP_TAPE, MAP_GIVEN };
enum { OP_X = 0, OP_CONST, OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_NEG, OP_SIN, OP_COS, OP_SQRT, OP_SQUARE };

typedef struct {
    int64_t S, K, P, B, M, L, F, R, joints;
    const double *weights;
    double *history, *x, *v, *pbest, *pcost, *gpos;
    const double *linear, *offset, *params, *lower, *upper, *constants, *tape_constants, *given;
    const int64_t *slot_of, *codes, *flags, *tape, *outputs;
} Batch;

static inline double larger(double current, double value) {
    return (current == current && !(value <= current)) ? value : current;
}

static void base_params(const Batch *b, int64_t s, double *registers, double *alpha) {
    const int64_t K = b->K, P = b->P, B = b->B, mode = b->flags[2];
    const double *x = b->x + s * K * P;
    if (mode == MAP_IDENTITY || mode == MAP_GIVEN) {
        const double *source = mode == MAP_IDENTITY ? x : b->given + s * K * B;
        const int64_t stride = mode == MAP_IDENTITY ? P : B;
        for (int64_t j = 0; j < B; j++)
            for (int64_t k = 0; k < K; k++) alpha[j * K + k] = source[k * stride + j];
        return;
    }
    for (int64_t row = 0; row < b->R; row++) {
        const int64_t op = b->tape[row * 4], out = b->tape[row * 4 + 1], a = b->tape[row * 4 + 2],
                      c = b->tape[row * 4 + 3];
        double *o = registers + out * K;
        const double *ra = registers + a * K, *rc = registers + c * K;
        for (int64_t k = 0; k < K; k++) {
            switch (op) {
            case OP_X: o[k] = x[k * P + a]; break;
            case OP_CONST: o[k] = b->tape_constants[row]; break;
            case OP_ADD: o[k] = ra[k] + rc[k]; break;
            case OP_SUB: o[k] = ra[k] - rc[k]; break;
            case OP_MUL: o[k] = ra[k] * rc[k]; break;
            case OP_DIV: o[k] = ra[k] / rc[k]; break;
            case OP_NEG: o[k] = -ra[k]; break;
            case OP_SIN: o[k] = sin(ra[k]); break;
            case OP_COS: o[k] = cos(ra[k]); break;
            case OP_SQRT: o[k] = sqrt(ra[k]); break;
            default: o[k] = ra[k] * ra[k];
            }
        }
    }
    for (int64_t j = 0; j < B; j++) memcpy(alpha + j * K, registers + b->outputs[j] * K, sizeof(double) * K);
}

static double spectral3(const double *e, int64_t K, int64_t k, int64_t samples) {
    double g00 = 0, g11 = 0, g22 = 0, g01 = 0, g12 = 0, g20 = 0;
    for (int64_t j = 0; j < samples; j++) {
        const double a = e[j * K + k], bb = e[(samples + j) * K + k], c = e[(2 * samples + j) * K + k];
        g00 += a * a;
        g11 += bb * bb;
        g22 += c * c;
        g01 += a * bb;
        g12 += bb * c;
        g20 += c * a;
    }
    const double q = (g00 + g11 + g22) / 3, x = g00 - q, y = g11 - q, z = g22 - q;
    const double off = g01 * g01 + g20 * g20 + g12 * g12;
    const double p = sqrt((x * x + y * y + z * z + 2 * off) / 6);
    const double det = x * (y * z - g12 * g12) - g01 * (g01 * z - g12 * g20) + g20 * (g01 * g12 - y * g20);
    double top;
    if (!(p > 0)) top = q;
    else {
        double r = det / (2 * p * p * p);
        r = r < -1.0 ? -1.0 : (r > 1.0 ? 1.0 : r);
        top = q + 2 * p * cos(acos(r) / 3);
    }
    return top > 0 ? sqrt(top) : (top != top ? top : 0.0);
}

static int compare(const void *a, const void *b) {
    const double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static void factor(const Batch *b, int64_t code, double parameter, const double *e, double *out, double *work) {
    const int64_t K = b->K, M = b->M, joints = b->joints, samples = M / joints;
    if (code == FRO) {
        for (int64_t k = 0; k < K; k++) out[k] = 0;
        for (int64_t m = 0; m < M; m++)
            for (int64_t k = 0; k < K; k++) out[k] += e[m * K + k] * e[m * K + k];
        for (int64_t k = 0; k < K; k++) out[k] = sqrt(out[k]);
    } else if (code == SPECTRAL) {
        for (int64_t k = 0; k < K; k++) out[k] = spectral3(e, K, k, samples);
    } else if (code == COLUMN_SUM || code == ROW_SUM || code == ROW_SQUARES) {
        const int64_t outer = code == COLUMN_SUM ? samples : joints, inner = code == COLUMN_SUM ? joints : samples;
        for (int64_t k = 0; k < K; k++) out[k] = -INFINITY;
        for (int64_t o = 0; o < outer; o++) {
            for (int64_t k = 0; k < K; k++) work[k] = 0;
            for (int64_t i = 0; i < inner; i++) {
                const double *row = e + (code == COLUMN_SUM ? i * samples + o : o * samples + i) * K;
                if (code == ROW_SQUARES)
                    for (int64_t k = 0; k < K; k++) work[k] += row[k] * row[k];
                else
                    for (int64_t k = 0; k < K; k++) work[k] += fabs(row[k]);
            }
            for (int64_t k = 0; k < K; k++) out[k] = larger(out[k], work[k]);
        }
    } else if (code == MAX_ABS) {
        for (int64_t k = 0; k < K; k++) out[k] = -INFINITY;
        for (int64_t m = 0; m < M; m++)
            for (int64_t k = 0; k < K; k++) out[k] = larger(out[k], fabs(e[m * K + k]));
    } else if (code == HUBER) {
        for (int64_t k = 0; k < K; k++) out[k] = 0;
        for (int64_t m = 0; m < M; m++)
            for (int64_t k = 0; k < K; k++) {
                const double a = fabs(e[m * K + k]), inner = a < parameter ? a : parameter;
                out[k] += inner * (a - 0.5 * inner);
            }
        for (int64_t k = 0; k < K; k++) out[k] /= M;
    } else { /* TRIMMED: the parameter is the number of smallest squares kept */
        const int64_t keep = (int64_t)parameter;
        for (int64_t k = 0; k < K; k++) {
            for (int64_t m = 0; m < M; m++) work[m] = e[m * K + k] * e[m * K + k];
            qsort(work, (size_t)M, sizeof(double), compare);
            double total = 0, nan = 0;
            for (int64_t m = 0; m < M; m++) nan += work[m] != work[m];
            for (int64_t m = 0; m < keep; m++) total += work[m];
            out[k] = nan ? NAN : total / keep;
        }
    }
}

static double evaluate(const Batch *b, int64_t s, const double *alpha, double *e, double *values, double *work) {
    const int64_t K = b->K, P = b->P, M = b->M, B = b->B, slot = b->slot_of[s];
    const double *linear = b->linear + slot * B * M, *offset = b->offset + slot * M;
    for (int64_t m = 0; m < M; m++) {
        for (int64_t k = 0; k < K; k++) e[m * K + k] = offset[m] + alpha[k] * linear[m];
        for (int64_t j = 1; j < B; j++)
            for (int64_t k = 0; k < K; k++) e[m * K + k] += alpha[j * K + k] * linear[j * M + m];
    }
    double *cost = values, *value = values + K;
    for (int64_t f = 0; f < b->F; f++) {
        const int64_t code = b->codes[slot * b->F + f];
        if (!code) break;
        factor(b, code, b->params[slot * b->F + f], e, value, work);
        for (int64_t k = 0; k < K; k++) cost[k] = f == 0 ? value[k] : cost[k] * value[k];
    }
    double *pcost = b->pcost + s * K, *pbest = b->pbest + s * K * P;
    const double *x = b->x + s * K * P;
    for (int64_t k = 0; k < K; k++)
        if (cost[k] < pcost[k]) {
            pcost[k] = cost[k];
            memcpy(pbest + k * P, x + k * P, sizeof(double) * P);
        }
    int64_t best = 0;
    double low = pcost[0];
    for (int64_t k = 1; k < K; k++)
        if (pcost[k] < low) {
            best = k;
            low = pcost[k];
        }
    memcpy(b->gpos + s * P, pbest + best * P, sizeof(double) * P);
    return low;
}

static void move(const Batch *b, int64_t s, double weight, const double *r1, const double *r2, const double *u3,
                 const double *vmax) {
    const int64_t K = b->K, P = b->P, boundary = b->flags[0], per_particle = b->flags[1];
    const double c1 = b->constants[0], c2 = b->constants[1];
    double *x = b->x + s * K * P, *v = b->v + s * K * P;
    const double *pbest = b->pbest + s * K * P, *g = b->gpos + s * P;
    const int64_t width = per_particle ? 1 : P;
    for (int64_t k = 0; k < K; k++)
        for (int64_t p = 0; p < P; p++) {
            const int64_t i = k * P + p, w = k * width + (per_particle ? 0 : p);
            const double position = x[i], low = b->lower[p], high = b->upper[p];
            double velocity = v[i] * weight + (c1 * r1[w]) * (pbest[i] - position);
            velocity = velocity + (c2 * r2[w]) * (g[p] - position);
            velocity = velocity < -vmax[p] ? -vmax[p] : velocity;
            velocity = velocity > vmax[p] ? vmax[p] : velocity;
            const double moved = position + velocity;
            if (boundary == CLAMP) {
                double clamped = moved < low ? low : moved;
                clamped = clamped > high ? high : clamped;
                v[i] = velocity * (clamped == moved ? 1.0 : 0.0);
                x[i] = clamped;
            } else if (boundary == REFLECT) {
                const double span = high - low;
                double t = moved - low;
                if (!(t >= -2 * span && t < 2 * span)) t = fmod(t, 2 * span);
                if (t < 0) t = t + 2 * span;
                const double folded = span - t;
                x[i] = high - fabs(folded);
                v[i] = velocity * ((folded > 0 ? 1.0 : 0.0) - (folded < 0 ? 1.0 : 0.0));
            } else {
                const double u = u3[w];
                if (moved < low) {
                    x[i] = low + (position - low) * u;
                    v[i] = 0;
                } else if (moved > high) {
                    x[i] = high - (high - position) * u;
                    v[i] = 0;
                } else {
                    x[i] = moved;
                    v[i] = velocity;
                }
            }
        }
}

static int run(const Batch *b, bitgen_t *rng, int64_t first, int64_t count, int64_t moves, int64_t last) {
    const int64_t K = b->K, P = b->P, B = b->B, M = b->M, boundary = b->flags[0];
    const int64_t width = b->flags[1] ? 1 : P, kinds = boundary == RANDOM ? 3 : 2, block = count * K * width;
    const double limit = b->constants[2];
    double *random = malloc(sizeof(double) * (size_t)(kinds * block));
    double *registers = malloc(sizeof(double) * (size_t)((b->R > 0 ? b->R : 1) * K));
    double *alpha = malloc(sizeof(double) * (size_t)(B * K));
    double *e = malloc(sizeof(double) * (size_t)(M * K));
    double *values = malloc(sizeof(double) * (size_t)(2 * K));
    double *work = malloc(sizeof(double) * (size_t)(M > K ? M : K));
    double *vmax = malloc(sizeof(double) * (size_t)P);
    int ok = random && registers && alpha && e && values && work && vmax;
    if (ok) {
        for (int64_t p = 0; p < P; p++) vmax[p] = limit > 0 ? limit * (b->upper[p] - b->lower[p]) : INFINITY;
        for (int64_t m = 0; m < moves + last; m++) {
            const int moving = m < moves;
            if (moving)
                for (int64_t i = 0; i < kinds * block; i++) random[i] = rng->next_double(rng->state);
            for (int64_t s = first; s < first + count; s++) {
                base_params(b, s, registers, alpha);
                b->history[m * count + (s - first)] = evaluate(b, s, alpha, e, values, work);
                if (moving) {
                    const double *r = random + (s - first) * K * width;
                    move(b, s, b->weights[m], r, r + block, r + (kinds - 1) * block, vmax);
                }
            }
        }
    }
    free(random);
    free(registers);
    free(alpha);
    free(e);
    free(values);
    free(work);
    free(vmax);
    return ok;
}

/* A C-contiguous buffer of the expected item size and dimensions. */
static int take(PyObject *object, Py_buffer *view, Py_ssize_t itemsize, int ndim, int writable) {
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(object, view, flags) < 0) return 0;
    if (view->itemsize != itemsize || view->ndim != ndim) {
        PyErr_Format(PyExc_ValueError, "kernel: expected a %d-d array of %zd-byte items", ndim, itemsize);
        PyBuffer_Release(view);
        return 0;
    }
    return 1;
}

static PyObject *run_trial(PyObject *self, PyObject *args) {
    PyObject *rng_object, *objects[21];
    Py_ssize_t first, count, joints;
    int last;
    if (!PyArg_ParseTuple(args, "OnnOpOOOOOOOOOOOnOOOOOOOO", &rng_object, &first, &count, &objects[0], &last,
                          &objects[1], &objects[2], &objects[3], &objects[4], &objects[5], &objects[6],
                          &objects[7], &objects[8], &objects[9], &objects[10], &objects[11], &joints,
                          &objects[12], &objects[13], &objects[14], &objects[15], &objects[16], &objects[17],
                          &objects[18], &objects[19]))
        return NULL;
    /* name, item size, dimensions, writable: the order of the arguments after `joints` included */
    static const struct {
        Py_ssize_t itemsize;
        int ndim, writable;
    } spec[20] = {{8, 1, 0}, {8, 2, 1}, {8, 3, 1}, {8, 3, 1}, {8, 3, 1}, {8, 2, 1}, {8, 2, 1},
                  {8, 3, 0}, {8, 2, 0}, {8, 1, 0}, {8, 2, 0}, {8, 2, 0}, {8, 1, 0}, {8, 1, 0},
                  {8, 1, 0}, {8, 1, 0}, {8, 2, 0}, {8, 1, 0}, {8, 1, 0}, {8, 3, 0}};
    Py_buffer views[20];
    int taken = 0;
    for (; taken < 20; taken++)
        if (!take(objects[taken], &views[taken], spec[taken].itemsize, spec[taken].ndim, spec[taken].writable))
            break;
    PyObject *result = NULL;
    PyObject *bit_generator = NULL, *capsule = NULL;
    if (taken == 20) {
        bit_generator = PyObject_GetAttrString(rng_object, "bit_generator");
        capsule = bit_generator ? PyObject_GetAttrString(bit_generator, "capsule") : NULL;
        bitgen_t *rng = capsule ? PyCapsule_GetPointer(capsule, "BitGenerator") : NULL;
        if (rng) {
            Batch b = {0};
            b.S = views[2].shape[0];
            b.K = views[2].shape[1];
            b.P = views[2].shape[2];
            b.L = views[7].shape[0];
            b.B = views[7].shape[1];
            b.M = views[7].shape[2];
            b.F = views[10].shape[1];
            b.R = views[16].shape[0];
            b.joints = joints;
            b.weights = views[0].buf;
            b.history = views[1].buf;
            b.x = views[2].buf;
            b.v = views[3].buf;
            b.pbest = views[4].buf;
            b.pcost = views[5].buf;
            b.gpos = views[6].buf;
            b.linear = views[7].buf;
            b.offset = views[8].buf;
            b.slot_of = views[9].buf;
            b.codes = views[10].buf;
            b.params = views[11].buf;
            b.lower = views[12].buf;
            b.upper = views[13].buf;
            b.constants = views[14].buf;
            b.flags = views[15].buf;
            b.tape = views[16].buf;
            b.tape_constants = views[17].buf;
            b.outputs = views[18].buf;
            b.given = views[19].buf;
            const int64_t moves = views[0].shape[0];
            int ok;
            Py_BEGIN_ALLOW_THREADS ok = run(&b, rng, first, count, moves, last);
            Py_END_ALLOW_THREADS if (ok) result = Py_NewRef(Py_None);
            else PyErr_NoMemory();
        }
    }
    Py_XDECREF(capsule);
    Py_XDECREF(bit_generator);
    for (int i = 0; i < taken; i++) PyBuffer_Release(&views[i]);
    return result;
}

static PyMethodDef methods[] = {{"run_trial", run_trial, METH_VARARGS, "kernel.run_trial, in C"}, {NULL, NULL, 0, NULL}};
static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_ckernel", NULL, -1, methods};
PyMODINIT_FUNC PyInit__ckernel(void) { return PyModule_Create(&module); }
