/* The symmetric N-body sum's inner loop alone, in C with AVX2 intrinsics: how fast can one
 * (receiver, source vector) step be on this CPU, before the block edges, near blocks and
 * reductions that the real kernel (rust_core/src/terms/pairwise_gravity.rs) adds? README,
 * "How far a direct sum can go on Zen 3 (avx2)", quotes its figures.
 *
 *   for m in 0 1 2 10 11 12; do
 *     gcc -O3 -funroll-loops -march=native -DMODE=$m benches/forces/nbody_inner_loop.c -o /tmp/nb && /tmp/nb
 *   done
 *
 * MODE (f64, 4 sources per vector): 0 the kernel's formulation (float32 estimate, one float32
 * Newton step, one third-order f64 step; every second receiver through vsqrtpd + vdivpd),
 * 1 every r^-3 as 1/(r^2 sqrt(r^2)), 2 raw vrsqrtps and a 4th-order series for r^-3.
 * MODE (f32, 8 sources per vector): 10 the kernel's (vrsqrtps, one Newton step, special-value
 * select, cube), 11 1/(r^2 sqrt(r^2)), 12 raw vrsqrtps and a 2nd-order series, no select.
 * Two receivers per tile (the AVX2 kernel's); N = 4096 uniform points; CLOCK_GHZ is the clock
 * the cycle counts assume (3.19 on the Zen 3 machine; measure yours). Single thread. */
#include <immintrin.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#define N 4096
#ifndef MODE
#define MODE 0
#endif
#ifndef CLOCK_GHZ
#define CLOCK_GHZ 3.19
#endif

#if MODE < 10
typedef double real;
typedef __m256d vec;
#define LANES 4
#define LOAD _mm256_loadu_pd
#define STORE _mm256_storeu_pd
#define SET1 _mm256_set1_pd
#define SUB _mm256_sub_pd
#define MUL _mm256_mul_pd
#define FMA _mm256_fmadd_pd
#define FNMA _mm256_fnmadd_pd
#define DIV _mm256_div_pd
#define SQRT _mm256_sqrt_pd
#define ADD _mm256_add_pd
#define ZERO _mm256_setzero_pd

static inline vec estimate(vec x) { /* the kernel's f64 1/sqrt at avx2 (x86.rs) */
  __m128 xf = _mm256_cvtpd_ps(x), y0 = _mm_rsqrt_ps(xf);
  __m128 hy = _mm_mul_ps(_mm_mul_ps(xf, _mm_set1_ps(0.5f)), y0);
  __m128 y1 = _mm_mul_ps(y0, _mm_fnmadd_ps(hy, y0, _mm_set1_ps(1.5f)));
  __m128 z = _mm_mul_ps(y1, _mm_setzero_ps());
  if (_mm_movemask_ps(_mm_cmpunord_ps(z, z))) return DIV(SET1(1), SQRT(x));
  vec y = _mm256_cvtps_pd(y1);
  vec e = FNMA(MUL(x, y), y, SET1(1));
  return FMA(MUL(y, e), FMA(e, SET1(0.375), SET1(0.5)), y);
}
static inline vec r3(vec x, int r) {
#if MODE == 0
  vec y = (r % 2) ? DIV(SET1(1), SQRT(x)) : estimate(x);
  return MUL(MUL(y, y), y);
#elif MODE == 1
  return DIV(SET1(1), MUL(x, SQRT(x)));
#else
  vec y = _mm256_cvtps_pd(_mm_rsqrt_ps(_mm256_cvtpd_ps(x)));
  vec y2 = MUL(y, y), y3 = MUL(y2, y), e = FNMA(x, y2, SET1(1));
  vec p = FMA(e, SET1(315.0 / 128), SET1(35.0 / 16));
  p = FMA(e, p, SET1(15.0 / 8));
  p = FMA(e, p, SET1(1.5));
  return FMA(MUL(y3, e), p, y3);
#endif
}
#else
typedef float real;
typedef __m256 vec;
#define LANES 8
#define LOAD _mm256_loadu_ps
#define STORE _mm256_storeu_ps
#define SET1 _mm256_set1_ps
#define SUB _mm256_sub_ps
#define MUL _mm256_mul_ps
#define FMA _mm256_fmadd_ps
#define FNMA _mm256_fnmadd_ps
#define DIV _mm256_div_ps
#define SQRT _mm256_sqrt_ps
#define ADD _mm256_add_ps
#define ZERO _mm256_setzero_ps
static inline vec r3(vec x, int r) {
  (void)r;
#if MODE == 10
  vec y0 = _mm256_rsqrt_ps(x);
  vec hy = MUL(MUL(x, SET1(0.5f)), y0);
  vec y = MUL(y0, FNMA(hy, y0, SET1(1.5f)));
  y = _mm256_blendv_ps(y0, y, _mm256_cmp_ps(y, y, _CMP_EQ_OQ));
  return MUL(MUL(y, y), y);
#elif MODE == 11
  return DIV(SET1(1.f), MUL(x, SQRT(x)));
#else
  vec y = _mm256_rsqrt_ps(x);
  vec y2 = MUL(y, y), y3 = MUL(y2, y), e = FNMA(x, y2, SET1(1.f));
  return FMA(MUL(y3, e), FMA(e, SET1(15.f / 8), SET1(1.5f)), y3);
#endif
}
#endif

#define R 2
static real xs[N], ys[N], zs[N], ms[N], cx[N], cy[N], cz[N], out[N];

/* Receivers i0, i0+1 against every source: row sums into out, reactions into the column sums. */
__attribute__((noinline)) static void tile(int i0) {
  vec xi[R][3], nmi[R], acc[R][3], eps2 = SET1((real)1e-4);
  for (int r = 0; r < R; r++) {
    xi[r][0] = SET1(xs[i0 + r]); xi[r][1] = SET1(ys[i0 + r]); xi[r][2] = SET1(zs[i0 + r]);
    nmi[r] = SET1(-ms[i0 + r]);
    acc[r][0] = acc[r][1] = acc[r][2] = ZERO();
  }
  for (int j = 0; j < N; j += LANES) {
    vec x = LOAD(xs + j), y = LOAD(ys + j), z = LOAD(zs + j), m = LOAD(ms + j);
    vec sx = LOAD(cx + j), sy = LOAD(cy + j), sz = LOAD(cz + j);
    for (int r = 0; r < R; r++) {
      vec dx = SUB(x, xi[r][0]), dy = SUB(y, xi[r][1]), dz = SUB(z, xi[r][2]);
      vec y3 = r3(FMA(dx, dx, FMA(dy, dy, FMA(dz, dz, eps2))), i0 + r);
      vec w = MUL(m, y3), wj = MUL(nmi[r], y3);
      acc[r][0] = FMA(w, dx, acc[r][0]); acc[r][1] = FMA(w, dy, acc[r][1]); acc[r][2] = FMA(w, dz, acc[r][2]);
      sx = FMA(wj, dx, sx); sy = FMA(wj, dy, sy); sz = FMA(wj, dz, sz);
    }
    STORE(cx + j, sx); STORE(cy + j, sy); STORE(cz + j, sz);
  }
  for (int r = 0; r < R; r++) {
    real t[LANES];
    STORE(t, ADD(acc[r][0], ADD(acc[r][1], acc[r][2])));
    for (int k = 0; k < LANES; k++) out[i0 + r] += t[k];
  }
}

int main(void) {
  srand(1);
  for (int i = 0; i < N; i++) {
    xs[i] = rand() / (real)RAND_MAX - 0.5f; ys[i] = rand() / (real)RAND_MAX - 0.5f;
    zs[i] = rand() / (real)RAND_MAX - 0.5f; ms[i] = (real)1 / N;
  }
  double best = 1e30;
  for (int rep = 0; rep < 5; rep++) {
    struct timespec a, b;
    clock_gettime(CLOCK_MONOTONIC, &a);
    long steps = 0;
    for (int it = 0; it < 4; it++)
      for (int i = 0; i + R <= N; i += R) { tile(i); steps += (long)R * (N / LANES); }
    clock_gettime(CLOCK_MONOTONIC, &b);
    double t = (b.tv_sec - a.tv_sec) + (b.tv_nsec - a.tv_nsec) * 1e-9;
    if (t * CLOCK_GHZ * 1e9 / steps < best) best = t * CLOCK_GHZ * 1e9 / steps;
  }
  printf("MODE %2d (%s): %.2f cycles per (receiver, %d-source vector)   [check %g]\n", MODE,
         MODE < 10 ? "f64" : "f32", best, LANES, (double)out[5]);
  return 0;
}
