/* dcslam's native kernels: loops that torch runs as many passes over an image, run here as one.
 *
 * Contract: each kernel gives the values of the torch code it stands for, bit for bit, on the machine it runs on
 * (tests/native/ compares the two). So the arithmetic below is that code's, in its order, with no contraction of
 * products into sums (built with -ffp-contract=off) except where the library doing torch's work contracts them:
 * torch.cross computes fma(a1, b2, -(a2 * b1)) where it was built for FMA, and MKL's 3 x 3 products sum by a chain of
 * FMAs outside its reproducible mode; the loader (dcslam/native/__init__.py) probes which this machine does. Square
 * roots are left to torch (MKL's, not always IEEE's): the kernels around them run in two passes.
 *
 * Built by the loader with the system's C compiler on first use, cached by the hash of this file and the flags.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* The normals of the pixel grid, dcslam.geometry.normals._grid_normals (search 1), in two passes around torch's own
 * square root (torch.sqrt is MKL's, which rounds a fraction of a per cent of its results otherwise than IEEE's sqrt):
 * GRID_NORMALS: each pixel's cross product of its tangents (normal, not yet unit) and the square to take the root of
 * (its squared norm where the pixel has a normal, 1 elsewhere); GRID_FINISH: the cross product divided by that root,
 * zeroed where the pixel has none, and turned to face the camera.
 * vertex: (3, H, W) planes; valid: (H, W) bytes 0/1; normal: (3, H, W); square, root: (H, W); ok: (H, W) out. */
#define GRID_NORMALS(NAME, T, ABS, FMA_EXPR)                                                                      \
    static void NAME(const T *vertex, const uint8_t *valid, int64_t H, int64_t W, T gap, T *normal,             \
                     T *square, uint8_t *ok_out) {                                                        \
        const int64_t HW = H * W;                                                                                \
        const T *X = vertex, *Y = vertex + HW, *Z = vertex + 2 * HW;                                             \
        for (int64_t i = 0; i < H; i++) {                                                                        \
            for (int64_t j = 0; j < W; j++) {                                                                    \
                const int64_t k = i * W + j;                                                                     \
                const int v = valid[k] != 0;                                                                     \
                /* P: the vertex where valid, +0 elsewhere (as choose(valid, vertex, 0)) */                      \
                const T p0 = v ? X[k] : (T)0, p1 = v ? Y[k] : (T)0, p2 = v ? Z[k] : (T)0;                        \
                const T limit = gap * p2;                                                                        \
                T s[4][3];                                                                                       \
                int sok[4];                                                                                      \
                /* right, left, down, up: the neighbour where it is valid and not across a depth edge, else P */ \
                const int64_t di[4] = {0, 0, 1, -1}, dj[4] = {1, -1, 0, 0};                                     \
                for (int d = 0; d < 4; d++) {                                                                    \
                    const int64_t a = i + di[d], b = j + dj[d];                                                  \
                    int use = 0;                                                                                 \
                    T q0 = 0, q1 = 0, q2 = 0;                                                                    \
                    if (a >= 0 && a < H && b >= 0 && b < W && valid[a * W + b]) {                                \
                        const int64_t m = a * W + b;                                                             \
                        q0 = X[m]; q1 = Y[m]; q2 = Z[m];                                                         \
                        use = ABS(q2 - p2) <= limit;                                                             \
                    }                                                                                            \
                    sok[d] = use;                                                                                \
                    s[d][0] = use ? q0 : p0; s[d][1] = use ? q1 : p1; s[d][2] = use ? q2 : p2;                   \
                }                                                                                                \
                const T tx0 = s[0][0] - s[1][0], tx1 = s[0][1] - s[1][1], tx2 = s[0][2] - s[1][2];               \
                const T ty0 = s[2][0] - s[3][0], ty1 = s[2][1] - s[3][1], ty2 = s[2][2] - s[3][2];               \
                T n0, n1, n2;                                                                                    \
                FMA_EXPR                                                                                         \
                const T norm2 = n0 * n0 + n1 * n1 + n2 * n2;                                                     \
                const int good = v && (sok[0] || sok[1]) && (sok[2] || sok[3]) && norm2 > (T)1e-20;              \
                const T m = good ? (T)1 : (T)0;                                                                  \
                normal[k] = n0; normal[HW + k] = n1; normal[2 * HW + k] = n2;                                    \
                square[k] = norm2 * m + ((T)1 - m);                                                              \
                ok_out[k] = (uint8_t)good;                                                                       \
            }                                                                                                    \
        }                                                                                                        \
    }

#define GRID_FINISH(NAME, T)                                                                                      \
    static void NAME(const T *vertex, const uint8_t *valid, const uint8_t *ok, const T *root, int64_t HW,        \
                     T *normal) {                                                                                 \
        const T *X = vertex, *Y = vertex + HW, *Z = vertex + 2 * HW;                                             \
        for (int64_t k = 0; k < HW; k++) {                                                                       \
            const int v = valid[k] != 0;                                                                         \
            const T p0 = v ? X[k] : (T)0, p1 = v ? Y[k] : (T)0, p2 = v ? Z[k] : (T)0;                            \
            const T m = ok[k] ? (T)1 : (T)0;                                                                     \
            const T n0 = normal[k] / root[k] * m, n1 = normal[HW + k] / root[k] * m,                             \
                    n2 = normal[2 * HW + k] / root[k] * m;                                                       \
            const T facing = (n0 * p0 + n1 * p1 + n2 * p2) > (T)0 ? (T)1 : (T)0;                                 \
            const T sign = (T)1 - (T)2 * facing;                                                                 \
            normal[k] = n0 * sign; normal[HW + k] = n1 * sign; normal[2 * HW + k] = n2 * sign;                   \
        }                                                                                                        \
    }

GRID_FINISH(grid_finish_f32, float)
GRID_FINISH(grid_finish_f64, double)

#define CROSS_FUSED(FMA)                                                                                          \
    n0 = FMA(tx1, ty2, -(tx2 * ty1)); n1 = FMA(tx2, ty0, -(tx0 * ty2)); n2 = FMA(tx0, ty1, -(tx1 * ty0));
#define CROSS_PLAIN                                                                                               \
    n0 = tx1 * ty2 - tx2 * ty1; n1 = tx2 * ty0 - tx0 * ty2; n2 = tx0 * ty1 - tx1 * ty0;

/* fmaf / fma are correctly rounded wherever they run; with the target "fma" the compiler emits the instruction */
__attribute__((target("fma"))) GRID_NORMALS(grid_normals_f32_fma_hw, float, fabsf, CROSS_FUSED(fmaf))
__attribute__((target("fma"))) GRID_NORMALS(grid_normals_f64_fma_hw, double, fabs, CROSS_FUSED(fma))
GRID_NORMALS(grid_normals_f32_fma_sw, float, fabsf, CROSS_FUSED(fmaf))
GRID_NORMALS(grid_normals_f64_fma_sw, double, fabs, CROSS_FUSED(fma))
GRID_NORMALS(grid_normals_f32_plain, float, fabsf, CROSS_PLAIN)
GRID_NORMALS(grid_normals_f64_plain, double, fabs, CROSS_PLAIN)

static int has_fma(void) {
    __builtin_cpu_init();
    return __builtin_cpu_supports("fma");
}

/* The variant of a kernel made by the macros above: as torch.cross without FMA (fused 0), or with it, by the
 * instruction where the CPU has one. */
#define DISPATCH(fused, kernel, ...)                                                                              \
    do {                                                                                                         \
        if (!(fused)) kernel##_plain(__VA_ARGS__);                                                               \
        else if (has_fma()) kernel##_fma_hw(__VA_ARGS__);                                                        \
        else kernel##_fma_sw(__VA_ARGS__);                                                                       \
    } while (0)

/* Exported: the float32 and float64 kernels; fused: 1 as torch.cross with FMA, 0 without. */
void dcslam_grid_normals_f32(const float *vertex, const uint8_t *valid, int64_t H, int64_t W, float gap,
                             float *normal, float *square, uint8_t *ok, int fused) {
    DISPATCH(fused, grid_normals_f32, vertex, valid, H, W, gap, normal, square, ok);
}

void dcslam_grid_normals_f64(const double *vertex, const uint8_t *valid, int64_t H, int64_t W, double gap,
                             double *normal, double *square, uint8_t *ok, int fused) {
    DISPATCH(fused, grid_normals_f64, vertex, valid, H, W, gap, normal, square, ok);
}

void dcslam_grid_finish_f32(const float *vertex, const uint8_t *valid, const uint8_t *ok, const float *root,
                            int64_t HW, float *normal) {
    grid_finish_f32(vertex, valid, ok, root, HW, normal);
}

void dcslam_grid_finish_f64(const double *vertex, const uint8_t *valid, const uint8_t *ok, const double *root,
                            int64_t HW, double *normal) {
    grid_finish_f64(vertex, valid, ok, root, HW, normal);
}

/* The normals of a sparse frame's valid pixels along its scan lines: dcslam.geometry.normals.point_normals, in two
 * passes around torch's square root as the grid's. points (N, 3) and idx (N,) their flat indices into (B, H, W) in
 * raster order; search, gap: point_normals' arguments. POINT_NORMALS writes each point's cross product of its
 * tangents along the row and the column into normal, the square to take the root of into square (its squared norm
 * where the point has a normal, 1 elsewhere) and ok; POINT_FINISH divides by the root, zeroes where not ok and turns
 * the normals to the camera. The column order is a counting sort of the points by column, stable, so each column's
 * points come by row: argsort's order, whose keys are unique. order: (N,) and count: (B W + 1,) scratch. */
#define SIDE(T, i, j, steps, use, q0, q1, q2)                                                                     \
    do {                                                                                                         \
        use = 0; q0 = P[3 * i]; q1 = P[3 * i + 1]; q2 = P[3 * i + 2];                                            \
        if ((j) >= 0) {                                                                                          \
            const T c0 = P[3 * (j)], c1 = P[3 * (j) + 1], c2 = P[3 * (j) + 2];                                  \
            const T zi = P[3 * i + 2];                                                                           \
            const T d = c2 - zi;                                                                                 \
            if ((d < 0 ? -d : d) <= gap * (T)(steps) * zi) { use = 1; q0 = c0; q1 = c1; q2 = c2; }               \
        }                                                                                                        \
    } while (0)

/* A point's line and its step along it, in the rows' order (raster) and in the columns' (by (b, u), then v) */
#define ROW_LINE(j) (idx[j] / W)
#define ROW_STEP(j) (idx[j] % W)
#define COL_LINE(j) ((idx[j] / HW) * W + idx[j] % W)
#define COL_STEP(j) ((idx[j] % HW) / W)

/* The neighbours of point ``at`` among the points next (jn) and previous (jp) in a line order (-1: none): nx and pv,
 * those on its line within ``search`` steps (else -1), sn and sp their steps away. */
#define NEAR(LINE, STEP, at, jn, jp)                                                                              \
    const int64_t sn = ((jn) >= 0 && LINE(jn) == LINE(at)) ? STEP(jn) - STEP(at) : search + 1;                  \
    const int64_t sp = ((jp) >= 0 && LINE(jp) == LINE(at)) ? STEP(at) - STEP(jp) : search + 1;                  \
    const int64_t nx = sn <= search ? (jn) : -1, pv = sp <= search ? (jp) : -1;

#define POINT_NORMALS(NAME, T, CROSS_EXPR, ATTR)                                                                  \
    ATTR static void NAME(const T *P, const int64_t *idx, int64_t N, int64_t B, int64_t H, int64_t W,           \
                          int64_t search, T gap, T *normal, T *square, uint8_t *ok, int64_t *order,              \
                          int64_t *count) {                                                                      \
        const int64_t HW = H * W;                                                                                \
        /* rows: the raster order is the scan-line order */                                                      \
        for (int64_t i = 0; i < N; i++) {                                                                        \
            NEAR(ROW_LINE, ROW_STEP, i, i + 1 < N ? i + 1 : -1, i > 0 ? i - 1 : -1)                              \
            int uf, ub; T f0, f1, f2, b0, b1, b2;                                                                \
            SIDE(T, i, nx, sn, uf, f0, f1, f2);                                                                  \
            SIDE(T, i, pv, sp, ub, b0, b1, b2);                                                                  \
            normal[3 * i] = f0 - b0; normal[3 * i + 1] = f1 - b1; normal[3 * i + 2] = f2 - b2;                   \
            ok[i] = (uint8_t)(uf | ub);                                                                          \
        }                                                                                                        \
        /* columns: a stable counting sort of the points by (b, u) */                                            \
        const int64_t lines = B * W;                                                                             \
        memset(count, 0, sizeof(int64_t) * (lines + 1));                                                        \
        for (int64_t i = 0; i < N; i++) count[COL_LINE(i) + 1]++;                                                \
        for (int64_t k = 0; k < lines; k++) count[k + 1] += count[k];                                            \
        for (int64_t i = 0; i < N; i++) order[count[COL_LINE(i)]++] = i;                                         \
        for (int64_t k = 0; k < N; k++) {                                                                        \
            const int64_t i = order[k];                                                                          \
            NEAR(COL_LINE, COL_STEP, i, k + 1 < N ? order[k + 1] : -1, k > 0 ? order[k - 1] : -1)                \
            int uf, ub; T f0, f1, f2, b0, b1, b2;                                                                \
            SIDE(T, i, nx, sn, uf, f0, f1, f2);                                                                  \
            SIDE(T, i, pv, sp, ub, b0, b1, b2);                                                                  \
            const T tx0 = normal[3 * i], tx1 = normal[3 * i + 1], tx2 = normal[3 * i + 2];                       \
            const T ty0 = f0 - b0, ty1 = f1 - b1, ty2 = f2 - b2;                                                 \
            T n0, n1, n2;                                                                                        \
            CROSS_EXPR                                                                                           \
            const T norm2 = n0 * n0 + n1 * n1 + n2 * n2;                                                         \
            const int good = ok[i] && (uf | ub) && norm2 > (T)1e-20;                                             \
            normal[3 * i] = n0; normal[3 * i + 1] = n1; normal[3 * i + 2] = n2;                                 \
            square[i] = good ? norm2 : (T)1;                                                                     \
            ok[i] = (uint8_t)good;                                                                               \
        }                                                                                                        \
    }

#define POINT_FINISH(NAME, T)                                                                                     \
    static void NAME(const T *P, const uint8_t *ok, const T *root, int64_t N, T *normal) {                       \
        for (int64_t i = 0; i < N; i++) {                                                                        \
            T n0 = normal[3 * i] / root[i], n1 = normal[3 * i + 1] / root[i], n2 = normal[3 * i + 2] / root[i];  \
            if (!ok[i]) n0 = n1 = n2 = (T)0;                                                                     \
            if (n0 * P[3 * i] + n1 * P[3 * i + 1] + n2 * P[3 * i + 2] > (T)0) { n0 = -n0; n1 = -n1; n2 = -n2; }  \
            normal[3 * i] = n0; normal[3 * i + 1] = n1; normal[3 * i + 2] = n2;                                  \
        }                                                                                                        \
    }

POINT_NORMALS(point_normals_f32_fma_hw, float, CROSS_FUSED(fmaf), __attribute__((target("fma"))))
POINT_NORMALS(point_normals_f64_fma_hw, double, CROSS_FUSED(fma), __attribute__((target("fma"))))
POINT_NORMALS(point_normals_f32_fma_sw, float, CROSS_FUSED(fmaf), )
POINT_NORMALS(point_normals_f64_fma_sw, double, CROSS_FUSED(fma), )
POINT_NORMALS(point_normals_f32_plain, float, CROSS_PLAIN, )
POINT_NORMALS(point_normals_f64_plain, double, CROSS_PLAIN, )
POINT_FINISH(point_finish_f32, float)
POINT_FINISH(point_finish_f64, double)

#define POINT_ARGS(T) const T *P, const int64_t *idx, int64_t N, int64_t B, int64_t H, int64_t W, int64_t search,    \
    T gap, T *normal, T *square, uint8_t *ok, int64_t *order, int64_t *count
#define POINT_CALL P, idx, N, B, H, W, search, gap, normal, square, ok, order, count

void dcslam_point_normals_f32(POINT_ARGS(float), int fused) { DISPATCH(fused, point_normals_f32, POINT_CALL); }

void dcslam_point_normals_f64(POINT_ARGS(double), int fused) { DISPATCH(fused, point_normals_f64, POINT_CALL); }

void dcslam_point_finish_f32(const float *P, const uint8_t *ok, const float *root, int64_t N, float *normal) {
    point_finish_f32(P, ok, root, N, normal);
}

void dcslam_point_finish_f64(const double *P, const uint8_t *ok, const double *root, int64_t N, double *normal) {
    point_finish_f64(P, ok, root, N, normal);
}

/* Voxel keys: dcslam.slam.pointmap.voxel_keys. Each coordinate divided by the voxel size (true division, as
 * torch.div by a number), floored, converted to int64 as the CPU converts (out of range or NaN: INT64_MIN), offset by
 * 2^20 (wrapping), clamped to [0, 2^21 - 1] and packed 21 bits each: (i << 42) | (j << 21) | k.
 * points (N, 3) -> keys (N,). */
#define VOXEL_KEYS(NAME, T, FLOOR)                                                                                \
    static void NAME(const T *points, int64_t N, T voxel, int64_t *keys) {                                       \
        for (int64_t i = 0; i < N; i++) {                                                                        \
            int64_t c[3];                                                                                        \
            for (int a = 0; a < 3; a++) {                                                                        \
                const T f = FLOOR(points[3 * i + a] / voxel);                                                    \
                const int64_t whole = (f >= (T)-0x1p63 && f < (T)0x1p63) ? (int64_t)f : INT64_MIN;              \
                const int64_t k = (int64_t)((uint64_t)whole + 1048576u);   /* wrapping, as torch's int64 add */ \
                c[a] = k < 0 ? 0 : (k > 2097151 ? 2097151 : k);                                                  \
            }                                                                                                    \
            keys[i] = (c[0] << 42) | (c[1] << 21) | c[2];                                                        \
        }                                                                                                        \
    }

VOXEL_KEYS(voxel_keys_f32, float, floorf)
VOXEL_KEYS(voxel_keys_f64, double, floor)

void dcslam_voxel_keys_f32(const float *points, int64_t N, float voxel, int64_t *keys) {
    voxel_keys_f32(points, N, voxel, keys);
}

void dcslam_voxel_keys_f64(const double *points, int64_t N, double voxel, int64_t *keys) {
    voxel_keys_f64(points, N, voxel, keys);
}

/* Open-addressing hash tables of non-negative int64 keys (voxel keys) to int64 values, -1 = empty; kept by each
 * thread (two: a map's keys and a frame's) and cleared per use. */
typedef struct { int64_t *keys, *values; size_t size; } Table;
static __thread Table tables[2] = {{NULL, NULL, 0}, {NULL, NULL, 0}};

static size_t table_open(Table *t, size_t n) {   /* its mask (a power of two >= 2 n, less 1); 0: no memory */
    size_t size = 16;
    while (size < 2 * n) size <<= 1;
    if (size > t->size) {
        free(t->keys); free(t->values);
        t->keys = malloc(size * sizeof(int64_t)); t->values = malloc(size * sizeof(int64_t));
        if (!t->keys || !t->values) {
            free(t->keys); free(t->values);
            t->keys = t->values = NULL; t->size = 0;
            return 0;
        }
        t->size = size;
    }
    memset(t->keys, 0xff, size * sizeof(int64_t));
    return size - 1;
}

static inline size_t probe(const Table *t, int64_t key, size_t mask) {   /* key's slot, or the empty one for it */
    uint64_t x = (uint64_t)key;                /* splitmix64's finaliser */
    x ^= x >> 30; x *= 0xbf58476d1ce4e5b9ULL; x ^= x >> 27; x *= 0x94d049bb133111ebULL; x ^= x >> 31;
    size_t h = (size_t)x & mask;
    while (t->keys[h] != -1 && t->keys[h] != key) h = (h + 1) & mask;
    return h;
}

/* dcslam.slam.pointmap.voxel_representatives after its keys: the index of the first key of each distinct value, in
 * increasing order (the first point of each voxel in input order). keys (N,) >= 0 -> first (Q,); returns Q, or -1
 * when memory ran out. */
int64_t dcslam_first_of_each(const int64_t *keys, int64_t N, int64_t *first) {
    Table *t = &tables[0];
    const size_t mask = table_open(t, (size_t)N);
    if (!mask) return -1;
    int64_t Q = 0;
    for (int64_t i = 0; i < N; i++) {
        const size_t h = probe(t, keys[i], mask);
        if (t->keys[h] == -1) { t->keys[h] = keys[i]; first[Q++] = i; }
    }
    return Q;
}

/* The lookups of dcslam.slam.pointmap.assign_voxels: the frame's points without a target (target < 0), their
 * distinct voxels in order of first appearance, and each voxel's map point (the map's keys are unique; -1: a new
 * voxel). map_keys (P,), keys and target (F,) -> free (M,) the points without a target, voxel_of (M,) each one's
 * voxel, voxels (D,) the distinct keys, slot (D,) their map points; returns D, with M in *n_free; -1: no memory;
 * -2: a key twice in the map (the torch code's answer then depends on its sort: it runs). */
int64_t dcslam_voxel_lookup(const int64_t *map_keys, int64_t P, const int64_t *keys, const int64_t *target, int64_t F,
                            int64_t *free_points, int64_t *voxel_of, int64_t *voxels, int64_t *slot, int64_t *n_free) {
    Table *map = &tables[0], *frame = &tables[1];
    const size_t map_mask = table_open(map, (size_t)P);
    if (!map_mask) return -1;
    for (int64_t i = 0; i < P; i++) {
        const size_t h = probe(map, map_keys[i], map_mask);
        if (map->keys[h] != -1) return -2;
        map->keys[h] = map_keys[i]; map->values[h] = i;
    }
    int64_t M = 0;
    for (int64_t i = 0; i < F; i++) M += target[i] < 0;
    const size_t mask = table_open(frame, (size_t)M);
    if (!mask) return -1;
    int64_t D = 0, m = 0;
    for (int64_t i = 0; i < F; i++) {
        if (target[i] >= 0) continue;
        const size_t h = probe(frame, keys[i], mask);
        if (frame->keys[h] == -1) {
            frame->keys[h] = keys[i]; frame->values[h] = D;
            const size_t g = probe(map, keys[i], map_mask);
            voxels[D] = keys[i]; slot[D] = map->keys[g] == -1 ? -1 : map->values[g];
            D++;
        }
        free_points[m] = i; voxel_of[m] = frame->values[h]; m++;
    }
    *n_free = M;
    return D;
}

/* The confidence-weighted averages of dcslam.slam.pointmap.merge: a map of P points and Q new slots (S = P + Q),
 * frame surfels i (F of them) into slots target[i]. The sums run as torch's index_add runs them (zero, then each
 * frame point in order, each product w_i x_i rounded first). Per slot j: wsum the frame weights, total = c + wsum
 * (c: the map point's confidence, 0 for a new slot), and each attribute (points, normals, colors: (.., 3); radius)
 * (c old + sum w x) / total where the slot was touched (wsum > 0), else old (0 for a new slot); observed the frame
 * points it took; square the averaged normal's squared norm where above 1e-20, else 1 (merge takes its root). */
#define MERGE(NAME, T)                                                                                            \
    static void NAME(int64_t P, int64_t Q, const int64_t *target, int64_t F, const T *weight, const T *conf,     \
                     const T *new3[3], const T *new_radius, const T *old3[3], const T *old_radius, T *out3[3],   \
                     T *out_radius, T *total, int64_t *observed, T *square) {                                    \
        const int64_t S = P + Q;                                                                                 \
        for (int64_t j = 0; j < S; j++) {                                                                        \
            total[j] = 0; observed[j] = 0; out_radius[j] = 0;                                                    \
            for (int a = 0; a < 3; a++) { out3[a][3 * j] = 0; out3[a][3 * j + 1] = 0; out3[a][3 * j + 2] = 0; }  \
        }                                                                                                        \
        for (int64_t i = 0; i < F; i++) { total[target[i]] += weight[i]; observed[target[i]] += 1; }            \
        for (int64_t i = 0; i < F; i++) {                                                                        \
            const int64_t j = target[i];                                                                         \
            const T w = weight[i];                                                                               \
            for (int a = 0; a < 3; a++)                                                                          \
                for (int c = 0; c < 3; c++) out3[a][3 * j + c] += (T)(w * new3[a][3 * i + c]);                   \
            out_radius[j] += (T)(w * new_radius[i]);                                                             \
        }                                                                                                        \
        for (int64_t j = 0; j < S; j++) {                                                                        \
            const T wsum = total[j], c = j < P ? conf[j] : (T)0;                                                 \
            const int touched = wsum > 0;                                                                        \
            const T t = c + wsum, safe = touched ? t : (T)1;                                                     \
            total[j] = t;                                                                                        \
            for (int a = 0; a < 3; a++)                                                                          \
                for (int k = 0; k < 3; k++) {                                                                    \
                    const T old = j < P ? old3[a][3 * j + k] : (T)0;                                             \
                    out3[a][3 * j + k] = touched ? ((T)(c * old) + out3[a][3 * j + k]) / safe : old;             \
                }                                                                                                \
            const T old_r = j < P ? old_radius[j] : (T)0;                                                        \
            out_radius[j] = touched ? ((T)(c * old_r) + out_radius[j]) / safe : old_r;                           \
            const T *n = out3[1] + 3 * j;                                                                        \
            const T n2 = (T)((T)(n[0] * n[0]) + (T)(n[1] * n[1])) + (T)(n[2] * n[2]);                            \
            square[j] = n2 > (T)1e-20 ? n2 : (T)1;                                                               \
        }                                                                                                        \
    }

MERGE(merge_f32, float)
MERGE(merge_f64, double)

void dcslam_merge_f32(int64_t P, int64_t Q, const int64_t *target, int64_t F, const float *weight, const float *conf,
                      const float *new_points, const float *new_normals, const float *new_colors,
                      const float *new_radius, const float *old_points, const float *old_normals,
                      const float *old_colors, const float *old_radius, float *points, float *normals,
                      float *colors, float *radius, float *total, int64_t *observed, float *square) {
    const float *n3[3] = {new_points, new_normals, new_colors}, *o3[3] = {old_points, old_normals, old_colors};
    float *out3[3] = {points, normals, colors};
    merge_f32(P, Q, target, F, weight, conf, n3, new_radius, o3, old_radius, out3, radius, total, observed, square);
}

void dcslam_merge_f64(int64_t P, int64_t Q, const int64_t *target, int64_t F, const double *weight,
                      const double *conf, const double *new_points, const double *new_normals,
                      const double *new_colors, const double *new_radius, const double *old_points,
                      const double *old_normals, const double *old_colors, const double *old_radius, double *points,
                      double *normals, double *colors, double *radius, double *total, int64_t *observed,
                      double *square) {
    const double *n3[3] = {new_points, new_normals, new_colors}, *o3[3] = {old_points, old_normals, old_colors};
    double *out3[3] = {points, normals, colors};
    merge_f64(P, Q, target, F, weight, conf, n3, new_radius, o3, old_radius, out3, radius, total, observed, square);
}

/* Rows times a 3 x 3 matrix, out = points @ M (dcslam.geometry.se3.rows_times, torch.mm): each entry a sum of
 * three products in the order MKL's kernel takes them; mode 0: each product rounded, summed left to right (MKL's
 * conditional-numerical-reproducibility mode, which dcslam sets); mode 1: fma(p2, m2, fma(p1, m1, p0 m0)) (MKL's own
 * AVX2 / AVX-512 kernels). The loader finds which one torch.mm is on this machine; neither: none is used. */
#define DOT3(T, FMA, mode, a0, a1, a2, b0, b1, b2)                                                                \
    ((mode) ? FMA(a2, b2, FMA(a1, b1, (T)(a0 * b0))) : ((T)((T)(a0 * b0) + (T)(a1 * b1)) + (T)(a2 * b2)))

#define ROWS_TIMES(NAME, T, FMA, ATTR)                                                                            \
    ATTR static void NAME(const T *points, const T *M, int64_t N, T *out, int mode) {                           \
        const T m00 = M[0], m01 = M[1], m02 = M[2], m10 = M[3], m11 = M[4], m12 = M[5];                          \
        const T m20 = M[6], m21 = M[7], m22 = M[8];                                                              \
        for (int64_t i = 0; i < N; i++) {                                                                        \
            const T a = points[3 * i], b = points[3 * i + 1], c = points[3 * i + 2];                             \
            out[3 * i] = DOT3(T, FMA, mode, a, b, c, m00, m10, m20);                                             \
            out[3 * i + 1] = DOT3(T, FMA, mode, a, b, c, m01, m11, m21);                                         \
            out[3 * i + 2] = DOT3(T, FMA, mode, a, b, c, m02, m12, m22);                                         \
        }                                                                                                        \
    }

ROWS_TIMES(rows_times_f32_hw, float, fmaf, __attribute__((target("fma"))))
ROWS_TIMES(rows_times_f64_hw, double, fma, __attribute__((target("fma"))))
ROWS_TIMES(rows_times_f32_sw, float, fmaf, )
ROWS_TIMES(rows_times_f64_sw, double, fma, )

void dcslam_rows_times_f32(const float *points, const float *M, int64_t N, float *out, int mode) {
    if (mode && has_fma()) rows_times_f32_hw(points, M, N, out, mode); else rows_times_f32_sw(points, M, N, out, mode);
}

void dcslam_rows_times_f64(const double *points, const double *M, int64_t N, double *out, int mode) {
    if (mode && has_fma()) rows_times_f64_hw(points, M, N, out, mode); else rows_times_f64_sw(points, M, N, out, mode);
}

/* One point-to-plane linearisation's pairs: dcslam.slam.odometry.PointToPlane.residuals with projective association
 * (dcslam.slam.association.ProjectiveAssociation), for every source point in one pass.
 * source, normals: (F, 3); usable: (F,) bytes or NULL; R, t: the pose's rotation (3 x 3, row-major) and translation;
 * RrT, tr: the rendering camera's R^T (contiguous, as the association keeps it) and translation; fx, fy, cx, cy: K's
 * entries; index: (height * width,) the rendered map's point per pixel (-1: none); table: (Q, 6) point, normal;
 * max_d2, cos_max: the gates; mode: rows_times' summation (above); exact_f32: v * width + u in the float type (else
 * in double). Out: r (M,), src (M,) ascending, q, n (M, 3); returns M, and the count before the gates in *paired
 * (the torch code rotates the paired normals with a product whose kernel depends on that count). J (M, 6) double or
 * NULL: PointToPlane.linearize's Jacobian rows, cat(n @ R, cross(source, n @ R)) in T then widened, the product by
 * rows_times' summation and the cross product as torch.cross (cross_fma: fused, as cross_fused finds). */
#define PAIRS(NAME, T, FMA, ATTR)                                                                                 \
    ATTR static int64_t NAME(const T *source, const T *normals, const uint8_t *usable, int64_t F, const T *R,    \
                             const T *t, const T *RrT, const T *tr, T fx, T fy, T cx, T cy, int64_t height,     \
                             int64_t width, const int64_t *index, const T *table, T max_d2, T cos_max, int mode,  \
                             int exact_f32, T *r, int64_t *src, T *q, T *n, int64_t *paired, int cross_fma,    \
                             double *J) {                                                                         \
        int64_t M = 0, P = 0;                                                                                    \
        const T W1 = (T)(width - 1), H1 = (T)(height - 1), Wf = (T)width, tiny = (T)1e-9;                        \
        for (int64_t i = 0; i < F; i++) {                                                                        \
            const T s0 = source[3 * i], s1 = source[3 * i + 1], s2 = source[3 * i + 2];                          \
            /* p = source @ R^T + t */                                                                           \
            const T p0 = DOT3(T, FMA, mode, s0, s1, s2, R[0], R[1], R[2]) + t[0];                                \
            const T p1 = DOT3(T, FMA, mode, s0, s1, s2, R[3], R[4], R[5]) + t[1];                                \
            const T p2 = DOT3(T, FMA, mode, s0, s1, s2, R[6], R[7], R[8]) + t[2];                                \
            /* the pixel in the rendering camera: (p @ RrT + tr), projected and rounded */                       \
            const T x = DOT3(T, FMA, mode, p0, p1, p2, RrT[0], RrT[3], RrT[6]) + tr[0];                          \
            const T y = DOT3(T, FMA, mode, p0, p1, p2, RrT[1], RrT[4], RrT[7]) + tr[1];                          \
            const T z = DOT3(T, FMA, mode, p0, p1, p2, RrT[2], RrT[5], RrT[8]) + tr[2];                          \
            const T zs = (z < 0 ? -z : z) > tiny ? z : tiny;                                                     \
            const T u = rint_t(fx * x / zs + cx), v = rint_t(fy * y / zs + cy);                                  \
            if (!(z > 0 && u >= 0 && u <= W1 && v >= 0 && v <= H1)) continue;                                    \
            const int64_t pixel = exact_f32 ? (int64_t)(v * Wf + u)                                             \
                                            : (int64_t)((double)v * (double)width + (double)u);                   \
            const int64_t target = index[pixel];                                                                 \
            if (target < 0) continue;                                                                            \
            P++;                                                                                                 \
            const T *row = table + 6 * target;                                                                   \
            const T d0 = p0 - row[0], d1 = p1 - row[1], d2 = p2 - row[2];                                        \
            const T o0 = normals[3 * i], o1 = normals[3 * i + 1], o2 = normals[3 * i + 2];                       \
            const T m0 = DOT3(T, FMA, mode, o0, o1, o2, R[0], R[1], R[2]);                                       \
            const T m1 = DOT3(T, FMA, mode, o0, o1, o2, R[3], R[4], R[5]);                                       \
            const T m2 = DOT3(T, FMA, mode, o0, o1, o2, R[6], R[7], R[8]);                                       \
            if (!(((T)(d0 * d0) + (T)(d1 * d1)) + (T)(d2 * d2) < max_d2)) continue;                              \
            if (!(((T)(m0 * row[3]) + (T)(m1 * row[4])) + (T)(m2 * row[5]) > cos_max)) continue;                 \
            if (usable && !usable[i]) continue;                                                                  \
            r[M] = ((T)(d0 * row[3]) + (T)(d1 * row[4])) + (T)(d2 * row[5]);                                     \
            src[M] = i;                                                                                          \
            q[3 * M] = row[0]; q[3 * M + 1] = row[1]; q[3 * M + 2] = row[2];                                     \
            n[3 * M] = row[3]; n[3 * M + 1] = row[4]; n[3 * M + 2] = row[5];                                     \
            if (J) {                                                                                             \
                /* (n @ R)_j = DOT3(n, column j of R); then cross(source, that) */                              \
                const T a0 = DOT3(T, FMA, mode, row[3], row[4], row[5], R[0], R[3], R[6]);                       \
                const T a1 = DOT3(T, FMA, mode, row[3], row[4], row[5], R[1], R[4], R[7]);                       \
                const T a2 = DOT3(T, FMA, mode, row[3], row[4], row[5], R[2], R[5], R[8]);                       \
                const T c0 = cross_fma ? FMA(s1, a2, -(s2 * a1)) : (T)(s1 * a2) - (T)(s2 * a1);                  \
                const T c1 = cross_fma ? FMA(s2, a0, -(s0 * a2)) : (T)(s2 * a0) - (T)(s0 * a2);                  \
                const T c2 = cross_fma ? FMA(s0, a1, -(s1 * a0)) : (T)(s0 * a1) - (T)(s1 * a0);                  \
                double *row6 = J + 6 * M;                                                                        \
                row6[0] = a0; row6[1] = a1; row6[2] = a2; row6[3] = c0; row6[4] = c1; row6[5] = c2;              \
            }                                                                                                    \
            M++;                                                                                                 \
        }                                                                                                        \
        *paired = P;                                                                                             \
        return M;                                                                                                \
    }

#define rint_t(x) _Generic((x), float: rintf, default: rint)(x)
PAIRS(pairs_f32_hw, float, fmaf, __attribute__((target("fma"))))
PAIRS(pairs_f64_hw, double, fma, __attribute__((target("fma"))))
PAIRS(pairs_f32_sw, float, fmaf, )
PAIRS(pairs_f64_sw, double, fma, )

#define PAIRS_ARGS(T) const T *source, const T *normals, const uint8_t *usable, int64_t F, const T *R, const T *t,  \
    const T *RrT, const T *tr, T fx, T fy, T cx, T cy, int64_t height, int64_t width, const int64_t *index,       \
    const T *table, T max_d2, T cos_max, int mode, int exact_f32, T *r, int64_t *src, T *q, T *n, int64_t *paired, \
    int cross_fma, double *J
#define PAIRS_CALL source, normals, usable, F, R, t, RrT, tr, fx, fy, cx, cy, height, width, index, table, max_d2,  \
    cos_max, mode, exact_f32, r, src, q, n, paired, cross_fma, J

int64_t dcslam_pairs_f32(PAIRS_ARGS(float)) {
    return (mode && has_fma()) ? pairs_f32_hw(PAIRS_CALL) : pairs_f32_sw(PAIRS_CALL);
}

int64_t dcslam_pairs_f64(PAIRS_ARGS(double)) {
    return (mode && has_fma()) ? pairs_f64_hw(PAIRS_CALL) : pairs_f64_sw(PAIRS_CALL);
}

/* Scratch memory kept by each thread between calls and grown as needed: a full image's buffers are megabytes, and
 * fresh ones cost a page fault per 4 kB every call (more than the work itself). */
static __thread unsigned char *scratch = NULL;
static __thread size_t scratch_bytes = 0;
static __thread int64_t *kept = NULL;   /* the last z-buffer's (pixel, point) pairs, until dcslam_take_pairs */
static __thread int64_t kept_count = 0;
/* The z-buffer's state, kept by each thread between calls: per centre pixel (of the padded window) its nearest depth
 * and owner, per pixel of the window the nearest covering depth, its rank and the point shown; each entry with the
 * stamp (call count) of the call that wrote it, so nothing is cleared between calls: stamps only ever hold earlier
 * counts, whatever the window's size was. Depths as double (a float converts exactly, and compares alike); one
 * entry is one cache line's part, as the points reach the pixels in no order. */
typedef struct { double z; int64_t owner; uint32_t stamp; } Centre;
typedef struct { double z; int64_t shown; uint32_t rank, stamp; } Cover;
static __thread uint32_t stamp = 0;
static __thread Centre *centres = NULL;
static __thread Cover *covers = NULL;
static __thread size_t n_centres = 0, n_covers = 0;
/* One bit per pixel of the window, set where this call covered it: the covered pixels are read off it in raster
 * order without reading every pixel's entry (sparse depth, drive 1000 of bench_slam.py, profiled: 3.0 -> 2.6 ms
 * a call). */
static __thread uint64_t *covered = NULL;
static __thread size_t n_covered = 0;

/* Growth by half again, and every page written at once: memory the kernels read before writing would otherwise be
 * the kernel's shared zero page, and each first write to it a copy-on-write fault that, with a second thread of the
 * process running on another core (dcslam slam's prefetch), flushes that core's TLB by an interrupt. The zeros go
 * through a volatile pointer to memset: called directly, the compiler folds malloc and memset(0) into calloc, which
 * leaves fresh pages unwritten, and a sparse map's z-buffer then reached new pages frame after frame (800 such
 * interrupts per 30 sparse frames). */
static void *(*volatile write_bytes)(void *, int, size_t) = memset;

static void *entries(void *array, size_t *size, size_t n, size_t item, size_t capacity) {
    if (n > *size) {
        free(array);
        n = capacity >= n ? capacity : n + n / 2;     /* the caller's bound, else half again */
        array = malloc(n * item);
        if (array) write_bytes(array, 0, n * item);   /* written once here (see write_bytes) */
        *size = array ? n : 0;
    }
    return array;
}

static void *grow(size_t bytes, size_t capacity) {
    if (bytes > scratch_bytes) {
        free(scratch);
        bytes = capacity >= bytes ? capacity : bytes + bytes / 2;
        scratch = malloc(bytes);
        if (scratch) write_bytes(scratch, 0, bytes);
        scratch_bytes = scratch ? bytes : 0;
    }
    return scratch;
}

/* The z-buffer of a map's points in a window of the image and its (2 splat + 1)^2 minimum filter:
 * dcslam.slam.pointmap._zbuffer_window. ids (N,), px (N, 2) (u, v) in the window (from -splat), z (N,); the window
 * is height x width pixels. Keeps the covered pixels (flat indices into the window, raster order) and the point
 * each shows for dcslam_take_pairs; returns their count, or -1 when memory ran out.
 * Ties as the torch code breaks them: of equal depths at one centre pixel the highest id; of equally near centres
 * covering a pixel the one at the largest offset (ky, kx) in that order (the torch code's separable filter keeps the
 * largest kx in each row, then the largest ky: the same centre). Done by spreading each centre over its square, so
 * the cost follows the points, not the window (a sparse map covers a few per cent of it). */
#define ZBUFFER(NAME, T)                                                                                          \
    static int64_t NAME(const int64_t *ids, const int64_t *px, const T *z, int64_t N, int64_t height,           \
                        int64_t width, int64_t splat, int64_t capacity) {                                        \
        const int64_t Wp = width + 2 * splat, Hp = height + 2 * splat, side = 2 * splat + 1;                     \
        const size_t n_pad = (size_t)(Hp * Wp), n_out = (size_t)(height * width), cap = (size_t)capacity;        \
        centres = entries(centres, &n_centres, n_pad, sizeof(Centre), cap);                                      \
        covers = entries(covers, &n_covers, n_out, sizeof(Cover), cap);                                          \
        const size_t words = (n_out + 63) / 64;                                                                  \
        covered = entries(covered, &n_covered, words, sizeof(uint64_t), (cap + 63) / 64);                        \
        int64_t *out = grow(2 * (n_out + 1) * sizeof(int64_t), 2 * (cap + 1) * sizeof(int64_t));                \
        if (!centres || !covers || !covered || !out) return -1;                                                  \
        memset(covered, 0, words * sizeof(uint64_t));                                                            \
        if (++stamp == 0) {                                                                                      \
            memset(centres, 0, n_centres * sizeof(Centre)); memset(covers, 0, n_covers * sizeof(Cover)); stamp = 1; \
        }                                                                                                        \
        const uint32_t now = stamp;                                                                              \
        for (int64_t i = 0; i < N; i++) {                                                                        \
            Centre *c = centres + (px[2 * i + 1] + splat) * Wp + (px[2 * i] + splat);                            \
            const double zi = (double)z[i];                                                                      \
            if (c->stamp != now) { c->stamp = now; c->z = zi; c->owner = -1; }                                    \
            else if (zi < c->z) c->z = zi;                                                                       \
        }                                                                                                        \
        for (int64_t i = 0; i < N; i++) {                                                                        \
            Centre *c = centres + (px[2 * i + 1] + splat) * Wp + (px[2 * i] + splat);                            \
            if ((double)z[i] <= c->z && ids[i] > c->owner) c->owner = ids[i];                                    \
        }                                                                                                        \
        /* each centre once: the point that owns it (its id is unique among the points) */                       \
        for (int64_t i = 0; i < N; i++) {                                                                        \
            const int64_t cr = px[2 * i + 1] + splat, cc = px[2 * i] + splat;                                    \
            const Centre *c = centres + cr * Wp + cc;                                                            \
            if (c->owner != ids[i] || !((double)z[i] <= c->z) || !isfinite(c->z)) continue;                      \
            const double zc = c->z;                                                                              \
            /* centre (R, C) in the padded image covers pixel (R - 2 splat + ky, C - 2 splat + kx) */            \
            for (int64_t ky = 0; ky < side; ky++) {                                                              \
                const int64_t v = cr - 2 * splat + ky;                                                           \
                if (v < 0 || v >= height) continue;                                                              \
                for (int64_t kx = 0; kx < side; kx++) {                                                          \
                    const int64_t u = cc - 2 * splat + kx;                                                       \
                    if (u < 0 || u >= width) continue;                                                           \
                    const int64_t k = v * width + u;                                                             \
                    Cover *p = covers + k;                                                                       \
                    const uint32_t r = (uint32_t)(ky * side + kx);                                               \
                    if (p->stamp != now || zc < p->z || (zc == p->z && r > p->rank)) {                           \
                        p->stamp = now; p->z = zc; p->rank = r; p->shown = c->owner;                             \
                        covered[k >> 6] |= (uint64_t)1 << (k & 63);                                              \
                    }                                                                                            \
                }                                                                                                \
            }                                                                                                    \
        }                                                                                                        \
        int64_t count = 0;                                                                                       \
        for (size_t w = 0; w < words; w++) {   /* the set bits, lowest first: raster order */                    \
            for (uint64_t bits = covered[w]; bits; bits &= bits - 1) {                                           \
                const size_t k = w * 64 + (size_t)__builtin_ctzll(bits);                                         \
                out[2 * count] = (int64_t)k; out[2 * count + 1] = covers[k].shown; count++;                      \
            }                                                                                                    \
        }                                                                                                        \
        kept = out; kept_count = count;                                                                          \
        return count;                                                                                            \
    }

ZBUFFER(zbuffer_f32, float)
ZBUFFER(zbuffer_f64, double)

/* capacity: the padded pixels of the whole image the windows lie in (0: unknown), allocated at once so that the
 * memory a run holds does not grow as its windows do. */
int64_t dcslam_zbuffer_window_f32(const int64_t *ids, const int64_t *px, const float *z, int64_t N, int64_t height,
                                  int64_t width, int64_t splat, int64_t capacity) {
    return zbuffer_f32(ids, px, z, N, height, width, splat, capacity);
}

int64_t dcslam_zbuffer_window_f64(const int64_t *ids, const int64_t *px, const double *z, int64_t N, int64_t height,
                                  int64_t width, int64_t splat, int64_t capacity) {
    return zbuffer_f64(ids, px, z, N, height, width, splat, capacity);
}

/* The last z-buffer's pixels and points of this thread, count of each (as that call returned). */
void dcslam_take_pairs(int64_t *pix, int64_t *hit, int64_t count) {
    for (int64_t i = 0; i < count && i < kept_count; i++) { pix[i] = kept[2 * i]; hit[i] = kept[2 * i + 1]; }
}

/* dcslam.slam.frame.prepare_frame's range gate in one pass: in[i] = lo <= d[i] <= hi (NaN: out of range), out[i] =
 * d[i] where in range, else +0 (the torch code: two comparisons, their and, torch.where with a zero); returns how
 * many are in range (the torch code's in_range.sum()). lo and hi as torch compares them: in the depth's type. */
#define DEPTH_RANGE(NAME, T)                                                                                      \
    int64_t NAME(const T *d, int64_t N, T lo, T hi, unsigned char *in, T *out) {                                 \
        int64_t count = 0;                                                                                       \
        for (int64_t i = 0; i < N; i++) {                                                                        \
            const T v = d[i];                                                                                    \
            const int k = (v >= lo) & (v <= hi);                                                                 \
            in[i] = (unsigned char)k; out[i] = k ? v : (T)0; count += k;                                         \
        }                                                                                                        \
        return count;                                                                                            \
    }

DEPTH_RANGE(dcslam_depth_range_f32, float)
DEPTH_RANGE(dcslam_depth_range_f64, double)

/* The version of this file's interface: the loader refuses a library of another. */
int dcslam_native_version(void) { return 2; }
