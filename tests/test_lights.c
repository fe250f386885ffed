/* The light tree (src/rt/lights.h) against what makes its picks unbiased, checked directly: at any
 * point the probabilities of all lights sum to at most 1 (less where a node's bounds allow light
 * that none of its children's tighter bounds do: the pick then returns none); a pick reports the probability bn__lights_pdf
 * gives for the light it returns; the frequencies of many picks match those probabilities; and no
 * light that can reach a point (some of it in front of the point's plane, the point in front of
 * the light's) ever has probability 0. Random triangles, normals and powers over ten decades; each
 * with every pick following the bounds, and with distant nodes choosing by power. */
#include "bn_test.h"
#include "base/internal.h"
#include "rt/lights.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

enum { NL = 300, NX = 40 };
static double FAR = 0;   /* each test runs with 0 and with a far threshold */

static void unit(bn__rng *r, double v[3])
{
    double z = 2 * bn__rng_uniform(r) - 1, ph = 2 * 3.14159265358979323846 * bn__rng_uniform(r), s = sqrt(1 - z * z);
    v[0] = s * cos(ph);
    v[1] = s * sin(ph);
    v[2] = z;
}

/* NL small triangles in a 10-unit cube (some clustered near the origin), their lights. */
static void make_lights(double *v, bn__light *l)
{
    bn__rng r = bn__rng_make(17, 0, 0);
    for (size_t i = 0; i < NL; i++) {
        double c[3], e1[3], e2[3], n[3], size = i % 3 == 0 ? 0.01 : 0.5, box = i % 5 == 0 ? 0.2 : 10;
        for (int k = 0; k < 3; k++)
            c[k] = box * (bn__rng_uniform(&r) - 0.5);
        unit(&r, e1);
        unit(&r, e2);
        for (int k = 0; k < 3; k++) {
            v[9 * i + k] = c[k];
            v[9 * i + 3 + k] = c[k] + size * e1[k];
            v[9 * i + 6 + k] = c[k] + size * e2[k];
        }
        n[0] = e1[1] * e2[2] - e1[2] * e2[1];
        n[1] = e1[2] * e2[0] - e1[0] * e2[2];
        n[2] = e1[0] * e2[1] - e1[1] * e2[0];
        double len = sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        l[i] = (bn__light){v + 9 * i, 3, {n[0] / len, n[1] / len, n[2] / len},
                           pow(10, 10 * bn__rng_uniform(&r) - 5)};
    }
}

/* Can light i reach x (normal n) at all: some corner strictly in front of x, x strictly in front. */
static int reaches(const bn__light *l, const double x[3], const double n[3])
{
    double d = 0;
    int front = 0;
    for (int k = 0; k < 3; k++)
        d += (x[k] - l->v[k]) * l->n[k];
    for (size_t c = 0; c < l->nv; c++) {
        double h = 0;
        for (int k = 0; k < 3; k++)
            h += (l->v[3 * c + k] - x[k]) * n[k];
        front |= h > 1e-9;
    }
    return d > 1e-9 && front;
}

static void never_miss(void)
{
    static double v[9 * NL];
    static bn__light l[NL];
    bn__rng r = bn__rng_make(99, 0, 0);
    bn__lights *t;
    make_lights(v, l);
    t = bn__lights_build(l, NL, 0);
    BN_ASSERT(t != NULL);
    BN_ASSERT_EQ(bn__lights_nodes(t), 2 * NL - 1);
    for (int j = 0; j < NX; j++) {
        double x[3], n[3], sum = 0, pdf;
        size_t reachable = 0;
        for (int k = 0; k < 3; k++)
            x[k] = (j % 4 == 0 ? 0.3 : 14) * (bn__rng_uniform(&r) - 0.5);
        unit(&r, n);
        for (size_t i = 0; i < NL; i++) {
            double p = bn__lights_pdf(t, x, n, i, FAR);
            BN_ASSERT(p >= 0 && p <= 1);
            if (reaches(&l[i], x, n)) {
                reachable++;
                BN_ASSERT(p > 0);
            }
            sum += p;
        }
        BN_ASSERT_LE(sum, 1 + 1e-9);
        if (reachable)
            BN_ASSERT(sum > 0);
        for (int s = 0; s < 50; s++) {
            size_t i = bn__lights_pick(t, x, n, bn__rng_uniform(&r), FAR, &pdf);
            if (i == BN__LIGHTS_NONE)
                continue;
            BN_ASSERT(i < NL);
            BN_ASSERT_REL(pdf, bn__lights_pdf(t, x, n, i, FAR), 1e-12);
        }
    }
    bn__lights_free(t);
}

/* 200,000 picks at one point: each light's count, and the count of no pick, within 5 standard
 * deviations of N p. */
static void frequencies(void)
{
    static double v[9 * NL];
    static bn__light l[NL];
    size_t count[NL + 1] = {0};
    const double x[3] = {1.0, -2.0, 0.5}, n[3] = {0, 0.6, 0.8};
    const size_t N = 200000;
    bn__rng r = bn__rng_make(5, 0, 0);
    bn__lights *t;
    double pdf;
    make_lights(v, l);
    BN_ASSERT((t = bn__lights_build(l, NL, 0)) != NULL);
    for (size_t s = 0; s < N; s++) {
        size_t i = bn__lights_pick(t, x, n, bn__rng_uniform(&r), FAR, &pdf);
        BN_ASSERT(i < NL || i == BN__LIGHTS_NONE);
        count[i < NL ? i : NL]++;
    }
    for (size_t i = 0; i <= NL; i++) {
        double p = 1, mean, sd;
        if (i < NL)
            p = bn__lights_pdf(t, x, n, i, FAR);
        else
            for (size_t j = 0; j < NL; j++)
                p -= bn__lights_pdf(t, x, n, j, FAR);
        mean = (double)N * p;
        sd = sqrt(mean * fmax(0, 1 - p));
        if (fabs((double)count[i] - mean) > 5 * sd + 1)
            BN_FAIL("light %zu: %zu picks, expected %.1f +- %.1f", i, count[i], mean, sd);
    }
    bn__lights_free(t);
}

BN_TEST(probabilities_never_miss_a_light)
{
    FAR = 0;
    never_miss();
    FAR = 0.3;   /* far nodes pick by power */
    never_miss();
}

BN_TEST(pick_frequencies_follow_the_probabilities)
{
    FAR = 0;
    frequencies();
    FAR = 0.3;
    frequencies();
}

/* 4,096 lights at one point (every split position costs the same): the tree stays shallow (cost
 * splits to depth 40, medians below: at most 40 + 12) and a pick's probability is still
 * bn__lights_pdf's. */
BN_TEST(coincident_lights_keep_the_tree_shallow)
{
    enum { N = 4096 };
    static const double v[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    static bn__light l[N];
    bn__lights *t;
    const double x[3] = {0.2, 0.3, 2}, n[3] = {0, 0, -1};
    double pdf;
    for (size_t i = 0; i < N; i++)
        l[i] = (bn__light){v, 3, {0, 0, 1}, 1};
    BN_ASSERT((t = bn__lights_build(l, N, 0)) != NULL);
    printf("depth %d for %d coincident lights\n", bn__lights_depth(t), N);
    BN_ASSERT_LE(bn__lights_depth(t), 52);
    for (int s = 0; s < 64; s++) {
        size_t i = bn__lights_pick(t, x, n, (s + 0.5) / 64, 0, &pdf);
        BN_ASSERT(i < N);
        BN_ASSERT_REL(pdf, bn__lights_pdf(t, x, n, i, 0), 1e-12);
        BN_ASSERT_REL(pdf, 1.0 / N, 1e-9);
    }
    bn__lights_free(t);
}
