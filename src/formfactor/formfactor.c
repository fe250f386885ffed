/* Form-factor assembly: F_ij = (1/A_i) int_Ai int_Aj cos(ti) cos(tj) V / (pi r^2) dAj dAi,
 * by three methods (analytic contour quadrature with shaft-culled shadow rays, stratified
 * Monte Carlo point pairs, cosine-weighted hemisphere rays), stored dense or CSR, with the
 * diagnostics every run reports. References: Cohen & Wallace, "Radiosity and Realistic Image
 * Synthesis" (1993) ch. 4; Haines & Wallace, "Shaft culling for efficient ray-traced radiosity"
 * (1991); Wallace, Elmquist & Haines, "A ray tracing algorithm for progressive radiosity" (1989). */
#include "bounce/formfactor.h"
#include "formfactor/ff_internal.h"
#include "formfactor/ff_io.h"
#include "formfactor/ff_pair.h"
#include "base/internal.h"
#include "base/vec.h"

#include <float.h>
#include <math.h>
#include <omp.h>
#include <string.h>

/* Entries above 1 by more than this are errors: room for the quadrature's rounding, far below
 * anything a wrong visibility or kernel produces (View3D's 1.31). */
#define BN__F_SLACK 1e-9
/* Row sums: hemisphere counts cannot exceed 1 but by rounding, so any excess is an error. The
 * analytic unoccluded part is exact to its tolerance but the visible fractions are sampled, so a
 * row of a closed scene may exceed 1 by sampling noise (a warning). A visible fraction from N
 * samples has a standard deviation of at most 0.5/sqrt(N), so a row above 1 by more than five of
 * those (and never less than 5%) is a wrong F, not noise, and an error. Monte Carlo rows are
 * statistical: warnings only. */
static double bn__rowsum_error(int samples)
{
    double five_sigma = 2.5 / sqrt((double)(samples > 0 ? samples : 1));
    return five_sigma > 0.05 ? five_sigma : 0.05;
}
#define BN__ROWSUM_ERROR bn__rowsum_error(bn__samples(o))

/* The form-factor methods in enum order (bn_ff_method). */
#define BN__FF_METHODS(X) X("analytic") X("montecarlo") X("hemisphere")
BN__VOCABULARY(bn_ff_method, bn_ff_method, BN__FF_METHODS)

/* The analytic method's visibility of partly occluded pairs: the exact visible part, or rays. */
#define BN__FF_VISIBILITIES(X) X("exact") X("rays")
static const char *const bn__ff_visibility_names[] = {BN__FF_VISIBILITIES(BN__NAME_ITEM)};
static const char bn__ff_visibility_list[] = BN__FF_VISIBILITIES(BN__NAME_BAR);

const char *bn_ff_visibility_name(int exact) { return bn__ff_visibility_names[exact ? 0 : 1]; }
const char *bn_ff_visibility_names(void) { return bn__ff_visibility_list + 1; }

int bn_ff_visibility_parse(const char *name, int *exact)
{
    int i = bn__name_find(bn__ff_visibility_names, 2, name);
    if (i >= 0)
        *exact = i == 0;
    return i >= 0 ? 0 : -1;
}

int bn_formfactor_default_samples(bn_ff_method m)
{
    return m == BN_FF_ANALYTIC ? 32 : m == BN_FF_MONTECARLO ? 64 : 4096;
}

void bn_formfactor_opts_default(bn_formfactor_opts *o)
{
    memset(o, 0, sizeof *o);
    o->method = BN_FF_ANALYTIC;
    o->samples = 0;
    o->storage = BN_STORAGE_DEFAULT;
    o->precision = BN_PRECISION_FLOAT;
    o->sparse_threshold = 0;
    o->max_memory = 0;
    o->seed = 1;
    o->tolerance = BN_FF_TOLERANCE_DEFAULT;
    o->exact_visibility = 1;
}

static int bn__samples(const bn_formfactor_opts *o)
{
    return o->samples > 0 ? o->samples : bn_formfactor_default_samples(o->method);
}

void bn_formfactor_opts_describe(const bn_formfactor_opts *o, char *buf, size_t size)
{
    snprintf(buf, size, "method=%s samples=%d seed=%llu precision=%s storage=%s sparse_threshold=%.17g tolerance=%.17g%s%s%s",
             bn_ff_method_name(o->method), bn__samples(o), (unsigned long long)o->seed,
             bn_precision_name(o->precision), o->storage ? o->storage : BN_STORAGE_DEFAULT, o->sparse_threshold,
             o->method == BN_FF_ANALYTIC ? (o->tolerance > 0 ? o->tolerance : BN_FF_TOLERANCE_DEFAULT) : 0.0,
             o->method == BN_FF_ANALYTIC && o->quadrature_only ? " quadrature_only=1" : "",
             o->method != BN_FF_ANALYTIC ? "" : " visibility=", o->method != BN_FF_ANALYTIC ? "" : bn_ff_visibility_name(o->exact_visibility));
}

/* ---- geometry shared by every pair ---- */

typedef struct bn__ffg {
    size_t n, nf;
    const bn_patch *patch;
    double *pv;          /* n * 4 corners xyz */
    double tol;          /* geometric tolerance: 1e-9 of the scene's diameter */
    double eps;          /* ray offset (bn_rt_epsilon) */
    double *fv;          /* nf * 4 corners */
    unsigned *fnc;
    double *fn, *flo, *fhi;
    bn__solids *solids;  /* convex solids among the faces (solids.c) */
} bn__ffg;

static void bn__ffg_free(bn__ffg *g)
{
    free(g->pv);
    free(g->fv);
    free(g->fnc);
    free(g->fn);
    free(g->flo);
    free(g->fhi);
    bn__solids_free(g->solids);
}

static bn_status bn__ffg_init(bn__ffg *g, const bn_scene *s, double eps, bn_error *err)
{
    size_t npv, nv, nfi;
    const double *pverts = bn_scene_patch_vertices(s, &npv), *verts = bn_scene_vertices(s, &nv);
    const size_t *fidx = bn_scene_face_indices(s, &nfi);
    const bn_face *faces;
    double lo[3], hi[3];
    memset(g, 0, sizeof *g);
    g->patch = bn_scene_patches(s, &g->n);
    faces = bn_scene_faces(s, &g->nf);
    g->pv = bn__malloc_array(g->n * 12, sizeof(double));
    g->fv = bn__malloc_array(g->nf * 12, sizeof(double));
    g->fnc = bn__malloc_array(g->nf, sizeof(unsigned));
    g->fn = bn__malloc_array(g->nf * 3, sizeof(double));
    g->flo = bn__malloc_array(g->nf * 3, sizeof(double));
    g->fhi = bn__malloc_array(g->nf * 3, sizeof(double));
    if (!g->pv || !g->fv || !g->fnc || !g->fn || !g->flo || !g->fhi) {
        bn__ffg_free(g);
        return bn_error_set(err, BN_ENOMEM, "out of memory for the geometry of %zu patches", g->n);
    }
    for (size_t i = 0; i < g->n; i++)
        for (unsigned k = 0; k < g->patch[i].ncorners; k++)
            memcpy(g->pv + 12 * i + 3 * k, pverts + 3 * g->patch[i].corner[k], 3 * sizeof(double));
    for (size_t f = 0; f < g->nf; f++) {
        g->fnc[f] = faces[f].nverts;
        memcpy(g->fn + 3 * f, faces[f].normal, 3 * sizeof(double));
        for (int c = 0; c < 3; c++) {
            g->flo[3 * f + c] = INFINITY;
            g->fhi[3 * f + c] = -INFINITY;
        }
        for (unsigned k = 0; k < faces[f].nverts; k++) {
            const double *v = verts + 3 * fidx[faces[f].first + k];
            memcpy(g->fv + 12 * f + 3 * k, v, 3 * sizeof(double));
            for (int c = 0; c < 3; c++) {
                g->flo[3 * f + c] = fmin(g->flo[3 * f + c], v[c]);
                g->fhi[3 * f + c] = fmax(g->fhi[3 * f + c], v[c]);
            }
        }
    }
    bn_scene_bounds(s, lo, hi);
    g->tol = 1e-9 * fmax(bn_v3_dist(lo, hi), 1e-300);
    g->eps = eps;
    {
        size_t *first = bn__malloc_array(g->nf ? g->nf : 1, sizeof *first);
        bn_status st = first ? BN_OK : BN_ENOMEM;
        for (size_t f = 0; first && f < g->nf; f++)
            first[f] = faces[f].first;
        if (st == BN_OK)
            st = bn__solids_find(g->fv, g->fnc, g->fn, fidx, first, g->nf, g->tol, &g->solids);
        free(first);
        if (st != BN_OK) {
            bn__ffg_free(g);
            return bn_error_set(err, st, "out of memory for the solids among %zu faces", g->nf);
        }
    }
    return BN_OK;
}

static const double *bn__pc(const bn__ffg *g, size_t i) { return g->pv + 12 * i; }

/* Largest signed distance of polygon v's corners from the plane (n, p). */
static double bn__max_height(const double *v, size_t nv, const double n[3], const double p[3])
{
    double m = -INFINITY;
    for (size_t k = 0; k < nv; k++) {
        double r[3];
        bn_v3_sub(v + 3 * k, p, r);
        m = fmax(m, bn_v3_dot(n, r));
    }
    return m;
}

/* Can i and j see each other's fronts at all? Coplanar and facing-away pairs cannot. */
static int bn__facing(const bn__ffg *g, size_t i, size_t j)
{
    const bn_patch *a = &g->patch[i], *b = &g->patch[j];
    if (i == j || a->face == b->face)
        return 0;
    return bn__max_height(bn__pc(g, j), b->ncorners, a->normal, bn__pc(g, i)) > g->tol &&
           bn__max_height(bn__pc(g, i), a->ncorners, b->normal, bn__pc(g, j)) > g->tol;
}

/* The parts of i in front of j and of j in front of i: only they exchange light. */
typedef struct bn__pair {
    double a[3 * BN__FF_POLY_MAX], b[3 * BN__FF_POLY_MAX];
    size_t na, nb;
    double Aa, Ab;
} bn__pair;

static int bn__pair_prep(const bn__ffg *g, size_t i, size_t j, bn__pair *p)
{
    const bn_patch *a = &g->patch[i], *b = &g->patch[j];
    if (!bn__facing(g, i, j))
        return 0;
    p->na = bn__poly_clip(bn__pc(g, i), a->ncorners, b->normal, bn__pc(g, j), g->tol, p->a);
    p->nb = bn__poly_clip(bn__pc(g, j), b->ncorners, a->normal, bn__pc(g, i), g->tol, p->b);
    if (!p->na || !p->nb)
        return 0;
    p->Aa = bn__poly_area(p->a, p->na, NULL);
    p->Ab = bn__poly_area(p->b, p->nb, NULL);
    return p->Aa > 0 && p->Ab > 0;
}

/* ---- shaft culling (Haines & Wallace 1991): can any face lie between the two polygons? ----
 * The shaft is the convex hull of the clipped polygons. A face cannot block a segment between
 * them if all its corners are outside (or on) one plane bounding the hull, or if the hull lies
 * on one side of the face's own plane. The test is conservative: "maybe" casts rays. */
#define BN__HULL_MAX (4 * BN__FF_POLY_MAX * BN__FF_POLY_MAX)

typedef struct bn__shaft {
    double s[6 * BN__FF_POLY_MAX];   /* hull points */
    size_t ns;
    double lo[3], hi[3];
    double pl[BN__HULL_MAX][4];      /* outward normal, offset */
    size_t npl;
    int hull_done;
} bn__shaft;

static void bn__hull_planes(bn__shaft *sh, const double *e, size_t ne, const double *v, size_t nv, double tol)
{
    for (size_t k = 0; k < ne; k++) {
        const double *a = e + 3 * k, *b = e + 3 * (k + 1 < ne ? k + 1 : 0);
        double ab[3];
        bn_v3_sub(b, a, ab);
        for (size_t m = 0; m < nv; m++) {
            double av[3], n[3], h, lo = INFINITY, hi = -INFINITY, len;
            bn_v3_sub(v + 3 * m, a, av);
            bn_v3_cross(ab, av, n);
            len = bn_v3_len(n);
            if (!(len > 1e-12 * bn_v3_dot(ab, ab) + 1e-300) || sh->npl >= BN__HULL_MAX)
                continue;
            bn_v3_scale(n, 1 / len, n);
            h = bn_v3_dot(n, a);
            for (size_t q = 0; q < sh->ns; q++) {
                double d = bn_v3_dot(n, sh->s + 3 * q) - h;
                lo = fmin(lo, d);
                hi = fmax(hi, d);
            }
            if (hi <= tol) {
                memcpy(sh->pl[sh->npl], n, sizeof n);
                sh->pl[sh->npl++][3] = h;
            } else if (lo >= -tol) {
                sh->pl[sh->npl][0] = -n[0];
                sh->pl[sh->npl][1] = -n[1];
                sh->pl[sh->npl][2] = -n[2];
                sh->pl[sh->npl++][3] = -h;
            }
        }
    }
}

/* cand: faces partly in front of patch i (row candidates). The faces that may block (up to max
 * of them, into out when it is not NULL); their count, so 0 when none can. */
static size_t bn__shaft_faces(const bn__ffg *g, const size_t *cand, size_t ncand, size_t i, size_t j, const bn__pair *p,
                              size_t *out_list, size_t max)
{
    size_t nout = 0;
    bn__shaft sh;
    const double *ni = g->patch[i].normal, *nj = g->patch[j].normal;
    size_t fi = g->patch[i].face, fj = g->patch[j].face;
    double tol = g->tol;
    sh.ns = p->na + p->nb;
    memcpy(sh.s, p->a, 3 * p->na * sizeof(double));
    memcpy(sh.s + 3 * p->na, p->b, 3 * p->nb * sizeof(double));
    for (int c = 0; c < 3; c++) {
        sh.lo[c] = INFINITY;
        sh.hi[c] = -INFINITY;
    }
    for (size_t q = 0; q < sh.ns; q++)
        for (int c = 0; c < 3; c++) {
            sh.lo[c] = fmin(sh.lo[c], sh.s[3 * q + c] - tol);
            sh.hi[c] = fmax(sh.hi[c], sh.s[3 * q + c] + tol);
        }
    sh.npl = 0;
    sh.hull_done = 0;
    for (size_t ci = 0; ci < ncand; ci++) {
        size_t f = cand[ci];
        const double *fv = g->fv + 12 * f, *fn = g->fn + 3 * f;
        unsigned nv = g->fnc[f];
        int out = 0;
        double lo = INFINITY, hi = -INFINITY;
        if (f == fi || f == fj)
            continue;
        for (int c = 0; c < 3 && !out; c++)
            out = g->fhi[3 * f + c] < sh.lo[c] || g->flo[3 * f + c] > sh.hi[c];
        if (out)
            continue;
        /* the hull on one side of the face's plane */
        for (size_t q = 0; q < sh.ns; q++) {
            double r[3], d;
            bn_v3_sub(sh.s + 3 * q, fv, r);
            d = bn_v3_dot(fn, r);
            lo = fmin(lo, d);
            hi = fmax(hi, d);
        }
        if (lo >= -tol || hi <= tol)
            continue;
        /* the face behind plane j (plane i is the row's candidate test) */
        if (bn__max_height(fv, nv, nj, p->b) <= tol || bn__max_height(fv, nv, ni, p->a) <= tol)
            continue;
        if (!sh.hull_done) {
            bn__hull_planes(&sh, p->a, p->na, p->b, p->nb, tol);
            bn__hull_planes(&sh, p->b, p->nb, p->a, p->na, tol);
            sh.hull_done = 1;
        }
        for (size_t k = 0; k < sh.npl && !out; k++) {
            double mn = INFINITY;
            for (unsigned q = 0; q < nv; q++)
                mn = fmin(mn, bn_v3_dot(sh.pl[k], fv + 3 * q) - sh.pl[k][3]);
            out = mn >= -tol;
        }
        if (!out) {
            if (out_list)
                out_list[nout] = f;
            if (++nout >= max)
                return nout;
        }
    }
    return nout;
}

/* ---- where F goes: the storage's builder ---- */

typedef bn_transport_builder bn__sink;

static void bn__sink_put(bn__sink *s, size_t i, size_t j, double v) { bn_transport_builder_put(s, i, j, v); }

/* The storage's pattern: row i's facing patches (the only possible nonzeros). */
static size_t bn__facing_cols(void *user, size_t i, uint32_t *cols)
{
    const bn__ffg *g = user;
    size_t m = 0;
    for (size_t j = 0; j < g->n; j++)
        if (bn__facing(g, i, j)) {
            if (cols)
                cols[m] = (uint32_t)j;
            m++;
        }
    return m;
}

/* ---- per-thread scratch for sampled pairs ---- */

typedef struct bn__scratch {
    size_t S;
    unsigned *perm;        /* 3 * S */
    double *x, *y, *w;     /* 3S, 3S, S */
    float *org, *dir, *tfar;
    unsigned char *blocked;
    double *row;           /* hemisphere counts, n */
} bn__scratch;

static void bn__scratch_free(bn__scratch *s)
{
    free(s->perm);
    free(s->x);
    free(s->y);
    free(s->w);
    free(s->org);
    free(s->dir);
    free(s->tfar);
    free(s->blocked);
    free(s->row);
}

static int bn__scratch_init(bn__scratch *s, size_t S, size_t n)
{
    memset(s, 0, sizeof *s);
    s->S = S;
    s->perm = bn__malloc_array(3 * S, sizeof(unsigned));
    s->x = bn__malloc_array(3 * S, sizeof(double));
    s->y = bn__malloc_array(3 * S, sizeof(double));
    s->w = bn__malloc_array(S, sizeof(double));
    s->org = bn__malloc_array(3 * S, sizeof(float));
    s->dir = bn__malloc_array(3 * S, sizeof(float));
    s->tfar = bn__malloc_array(S, sizeof(float));
    s->blocked = bn__malloc_array(S, 1);
    s->row = n ? bn__calloc(n, sizeof(double)) : NULL;
    return s->perm && s->x && s->y && s->w && s->org && s->dir && s->tfar && s->blocked && (!n || s->row);
}

/* Three random permutations of 0..S-1 (a 4-D Latin hypercube with the sample index). */
static void bn__perms(bn__rng *r, unsigned *perm, size_t S)
{
    for (int d = 0; d < 3; d++) {
        unsigned *p = perm + d * S;
        for (size_t k = 0; k < S; k++)
            p[k] = (unsigned)k;
        for (size_t k = S; k > 1; k--) {
            size_t m = (size_t)(bn__rng_uniform(r) * (double)k);
            unsigned t = p[k - 1];
            if (m >= k)
                m = k - 1;
            p[k - 1] = p[m];
            p[m] = t;
        }
    }
}

/* Stratified point pairs x_k on a, y_k on b (Latin hypercube over the four coordinates). */
static void bn__pair_points(bn__rng *r, const bn__pair *p, bn__scratch *s)
{
    size_t S = s->S;
    double inv = 1.0 / (double)S;
    bn__perms(r, s->perm, S);
    for (size_t k = 0; k < S; k++) {
        double u1 = ((double)k + bn__rng_uniform(r)) * inv, v1 = ((double)s->perm[k] + bn__rng_uniform(r)) * inv;
        double u2 = ((double)s->perm[S + k] + bn__rng_uniform(r)) * inv;
        double v2 = ((double)s->perm[2 * S + k] + bn__rng_uniform(r)) * inv;
        bn__poly_sample(p->a, p->na, u1, v1, s->x + 3 * k);
        bn__poly_sample(p->b, p->nb, u2, v2, s->y + 3 * k);
    }
}

/* Tries of the rejection step below before its last candidate is taken: the acceptance rate is
 * the mean of n.w over the polygon's solid angle divided by its maximum, above 1/2 but for
 * extreme grazing polygons, so 2^-64 or less is the chance of reaching it. */
#define BN__COS_TRIES 64

/* Sample k of S in four dimensions, stratified in each (Latin hypercube over s->perm, which
 * bn__perms filled): u1 by k, the others by the three permutations. */
static void bn__lhs4(bn__rng *r, const bn__scratch *s, size_t k, double *u1, double *v1, double *u2, double *v2)
{
    size_t S = s->S;
    double inv = 1.0 / (double)S;
    *u1 = ((double)k + bn__rng_uniform(r)) * inv;
    *v1 = ((double)s->perm[k] + bn__rng_uniform(r)) * inv;
    *u2 = ((double)s->perm[S + k] + bn__rng_uniform(r)) * inv;
    *v2 = ((double)s->perm[2 * S + k] + bn__rng_uniform(r)) * inv;
}

/* Point pairs distributed as the kernel, for the visible fraction of the analytic method:
 * x_k stratified uniformly on a, y_k on b with density proportional to cos(ti) cos(tj) / r^2
 * given x_k (a direction uniform in b's solid angle from x_k, kept with probability
 * n_i.w / cmax: cosine-weighted), and the weight w_k = F(x_k -> b) from the contour integral.
 * Then E[w_k V_k] = int_b k(x_k, y) V dy / pi and E[w_k] = F(x_k -> b): no 1/r^2 in any weight,
 * so nothing to regularise, and every weight lies in [0, 1]. */
static void bn__kernel_points(bn__rng *r, const bn__pair *p, const double ni[3], const double nj[3], bn__scratch *s)
{
    size_t S = s->S;
    bn__perms(r, s->perm, S);
    for (size_t k = 0; k < S; k++) {
        double u1, v1, u2, v2, *x = s->x + 3 * k, *y = s->y + 3 * k, dir[3] = {0, 0, 0}, h;
        bn__sph_poly sp;
        bn__lhs4(r, s, k, &u1, &v1, &u2, &v2);
        bn__poly_sample(p->a, p->na, u1, v1, x);
        s->w[k] = bn__ff_point_polygon(x, ni, p->b, p->nb);
        memcpy(y, x, 3 * sizeof(double));
        if (!(s->w[k] > 0) || !bn__sph_poly_init(&sp, x, ni, p->b, p->nb)) {
            s->w[k] = 0;   /* x sees none of b: no ray */
            continue;
        }
        for (int t = 0; t < BN__COS_TRIES; t++) {
            /* the stratified pair first, fresh numbers for the retries */
            bn__sph_poly_sample(&sp, t ? bn__rng_uniform(r) : u2, t ? bn__rng_uniform(r) : v2, dir);
            if (bn__rng_uniform(r) * sp.cmax < bn_v3_dot(ni, dir))
                break;
        }
        /* y: where x + t dir meets b's plane */
        h = -bn_v3_dot(nj, dir);
        if (h > 0) {
            double r0[3];
            bn_v3_sub(p->b, x, r0);
            bn_v3_madd(x, -bn_v3_dot(nj, r0) / h, dir, y);
        }
    }
}

/* Point pairs for separated patches: x on a and y on b uniform in area (stratified, Latin
 * hypercube), weighted by the kernel cos cos / r^2, which is bounded there; the visible fraction
 * is then sum w V / sum w as with the kernel's own directions, at a fraction of their cost (no
 * solid angle per point). Near pairs need the directions: there the kernel varies too fast. */
static void bn__area_points(bn__rng *r, const bn__pair *p, const double ni[3], const double nj[3], bn__scratch *s)
{
    size_t S = s->S;
    bn__perms(r, s->perm, S);
    for (size_t k = 0; k < S; k++) {
        double u1, v1, u2, v2, *x = s->x + 3 * k, *y = s->y + 3 * k, d[3], r2, cx, cy;
        bn__lhs4(r, s, k, &u1, &v1, &u2, &v2);
        bn__poly_sample(p->a, p->na, u1, v1, x);
        bn__poly_sample(p->b, p->nb, u2, v2, y);
        bn_v3_sub(y, x, d);
        r2 = bn_v3_dot(d, d);
        cx = bn_v3_dot(ni, d);
        cy = -bn_v3_dot(nj, d);
        s->w[k] = r2 > 0 && cx > 0 && cy > 0 ? cx * cy / (r2 * r2) : 0;
    }
}

/* Shadow rays between the point pairs: origins offset off the surfaces, stopping short. */
static size_t bn__pair_rays(const bn_rt *rt, const bn__ffg *g, const double ni[3], const double nj[3], bn__scratch *s)
{
    size_t m = 0;
    for (size_t k = 0; k < s->S; k++) {
        double o[3], t[3], d[3], len;
        bn_v3_madd(s->x + 3 * k, g->eps, ni, o);
        bn_v3_madd(s->y + 3 * k, g->eps, nj, t);
        bn_v3_sub(t, o, d);
        len = bn_v3_len(d);
        s->blocked[k] = 0;
        if (s->w[k] <= 0 || len <= 4 * g->eps)
            continue;
        for (int c = 0; c < 3; c++) {
            s->org[3 * m + c] = (float)o[c];
            s->dir[3 * m + c] = (float)d[c];
        }
        s->tfar[m] = (float)(1.0 - g->eps / len);
        s->perm[m] = (unsigned)k;   /* reuse: ray -> sample */
        m++;
    }
    if (m) {
        bn_rt_occluded_batch(rt, s->org, s->dir, s->tfar, m, s->blocked);
        /* blocked[0..m) is per ray; spread back to samples from the top down (ray r <= sample). */
        for (size_t q = m; q-- > 0;) {
            unsigned char v = s->blocked[q];
            size_t k = s->perm[q];
            s->blocked[q] = 0;
            s->blocked[k] = v;
        }
    }
    return m;
}

/* ---- the assembly ---- */

typedef struct bn__counts {
    size_t pairs_nonzero, pairs_culled, pairs_tested, pairs_blocked, pairs_exact, rays, evals;
} bn__counts;

/* The visible part's relative tolerance: its error estimate adds refinement beyond the fixed
 * splits (bn__exact_visible), which decide the accuracy where shadows crease the integrand
 * (on the Cornell box 1e-1 and 1 give the same row sums). */
#define BN__VIS_RTOL 1e-1

/* The other patch touches an occluder when it comes within this share of its diameter of one. */
#define BN__VIS_SLIVER_NEAR 0.1

/* Rows of a closed scene may exceed 1 by this much with exact visibility (issue 15's bound; measured
 * up to 2e-5 on the Cornell box, 3.2e-5 and 7.5e-5 in closed rooms with blocks). */
#define BN__VIS_ROW_ALLOWANCE 1e-4

/* The largest distance between two corners of polygon v. */
static double bn__diam(const double *v, size_t nv)
{
    double d = 0;
    for (size_t k = 0; k < nv; k++)
        for (size_t m = k + 1; m < nv; m++)
            d = fmax(d, bn_v3_dist(v + 3 * k, v + 3 * m));
    return d;
}

/* How near the occluders come to polygon v (nv corners, normal n, diameter diam), over its
 * diameter: the least distance between a corner of one and the other polygon. */
static double bn__occ_nearness(const bn__ffg *g, const double *v, size_t nv, const double n[3], double diam,
                               const size_t *occ, size_t nocc)
{
    double d = INFINITY;
    for (size_t q = 0; q < nocc; q++) {
        const double *fv = g->fv + 12 * occ[q];
        unsigned fn = g->fnc[occ[q]];
        for (unsigned k = 0; k < fn; k++)
            d = fmin(d, bn__point_polygon_dist(fv + 3 * k, v, nv, n));
        for (size_t k = 0; k < nv; k++)
            d = fmin(d, bn__point_polygon_dist(v + 3 * k, fv, fn, g->fn + 3 * occ[q]));
    }
    return diam > 0 ? d / diam : 0;
}

/* Does face f block every segment between the pair's polygons? The points from which a segment to
 * a given point meets a convex set K form a convex set (K's shadow), so every segment from one
 * convex polygon to another meets K when the segments between their corners do (once over the
 * second polygon for each corner of the first, then over the first). K is the face shrunk by tol:
 * each corner segment must cross the face's plane between its ends and at least tol inside its
 * edges. */
static int bn__face_blocks_all(const bn__ffg *g, size_t f, const bn__pair *p)
{
    const double *fv = g->fv + 12 * f, *fn = g->fn + 3 * f;
    unsigned nv = g->fnc[f];
    double tol = g->tol;
    for (size_t m = 0; m < p->na; m++)
        for (size_t k = 0; k < p->nb; k++) {
            const double *a = p->a + 3 * m, *b = p->b + 3 * k;
            double ra[3], rb[3], da, db, y[3], d[3];
            int side = 0;
            bn_v3_sub(a, fv, ra);
            bn_v3_sub(b, fv, rb);
            da = bn_v3_dot(fn, ra);
            db = bn_v3_dot(fn, rb);
            if (!((da > tol && db < -tol) || (da < -tol && db > tol)))
                return 0;
            bn_v3_sub(b, a, d);
            bn_v3_madd(a, da / (da - db), d, y);   /* where the segment crosses the plane */
            for (unsigned e = 0; e < nv; e++) {
                const double *c0 = fv + 3 * e, *c1 = fv + 3 * (e + 1 < nv ? e + 1 : 0);
                double ev[3], ry[3], cr[3], s;
                bn_v3_sub(c1, c0, ev);
                bn_v3_sub(y, c0, ry);
                bn_v3_cross(ev, ry, cr);
                s = bn_v3_dot(cr, fn);   /* |ev| times y's distance inside (or outside) the edge */
                if (fabs(s) <= tol * bn_v3_len(ev) || (side && (s > 0) != (side > 0)))
                    return 0;
                side = s > 0 ? 1 : -1;
            }
        }
    return 1;
}

/* Per occluder, the plane that leaves it out where it is seen from behind (bn__ff_point_blocked's cull):
 * a face of a convex solid that neither patch is on, when every point x of polygon v (the integrated
 * patch) is outside the solid (bn__solid_back_faces_hidden); NAN offset otherwise. Cornell box: 12.0 M of
 * the 27.2 M faces the points would clip (44%), and 28% of the form factors' CPU time. */
static void bn__cull_planes(const bn__ffg *g, const size_t *occ, size_t nocc, size_t i, size_t j, const double *v,
                            size_t nv, double *cull)
{
    size_t si = bn__solid_of(g->solids, g->patch[i].face), sj = bn__solid_of(g->solids, g->patch[j].face);
    for (size_t q = 0; q < nocc; q++) {
        size_t k = bn__solid_of(g->solids, occ[q]);
        cull[4 * q + 3] = NAN;
        if (k != SIZE_MAX && k != si && k != sj && bn__solid_back_faces_hidden(g->solids, k, v, nv, g->tol) &&
            !bn__solid_face_plane(g->solids, k, g->fn + 3 * occ[q], g->fv + 12 * occ[q], g->tol, cull + 4 * q))
            cull[4 * q + 3] = NAN;
    }
}

/* A_i F_ij with visibility for a pair whose shaft holds at most BN__VIS_OCC_MAX faces, none of
 * which hides it wholly (bn__face_blocks_all, tried first by the caller), exactly: I, the
 * unoccluded value (closed form), minus the integral over one patch of the part of the other that
 * the occluders hide from each point (bn__ff_point_blocked), clamped to [0, I]. No shadow rays.
 * - The blocked part is 0 wherever no occluder is in view, so the rules spend nothing there and the
 *   unoccluded kernel's own peaks (shared edges, near pairs) are left to the closed form.
 * - It is continuous but creased where shadow edges cross the patch, over widths that scale with
 *   the patch's distance from the occluders (a point by a block's corner sees a far wall appear
 *   within a few millimetres), and with the other patch's size. So the patch the occluders keep
 *   farther from, relative to its size, is integrated (what the other sees is exact whatever its
 *   distance); each of its fan triangles starts as 4 (28 points), or 16 when an occluder comes
 *   within the patch's diameter of it, and 4 times more for each halving of the other patch's
 *   size below it when that patch touches an occluder (a sliver cut along a contact line,
 *   against a wall: shadow bands as narrow as the sliver), up to 64; triangles whose points
 *   disagree about whether an occluder is in view are split further (kernel.c); then the
 *   adaptive rule to BN__VIS_RTOL of its own error estimate.
 * Measured on the Cornell box (1,151 patches): the largest row sum above 1 is 2.9e-3 with 32
 * shadow rays, 8.7e-5 from 20 points per pair adaptively, 1.7e-5 with the splits. In a closed room
 * with two blocks standing on its floor, the worst |row sum - 1| is 1.2e-4 without the sliver
 * rule, 7.5e-5 with it. */
static double bn__exact_visible(const bn__ffg *g, double I, size_t i, size_t j, const bn__pair *p,
                                const size_t *occ, size_t nocc, bn__counts *cnt)
{
    double ov[12 * BN__VIS_OCC_MAX], cull[4 * BN__VIS_OCC_MAX], G;
    double da = bn__diam(p->a, p->na), db = bn__diam(p->b, p->nb);
    unsigned on[BN__VIS_OCC_MAX];
    bn__quad_stats qs;
    const double *ni = g->patch[i].normal, *nj = g->patch[j].normal;
    double na = bn__occ_nearness(g, p->a, p->na, ni, da, occ, nocc), nb = bn__occ_nearness(g, p->b, p->nb, nj, db, occ, nocc);
    int from_b = nb > na, split = (from_b ? nb : na) < 1 ? 2 : 1;
    /* the integrated patch's size over the other's, when that one touches an occluder */
    double ratio = (from_b ? na : nb) < BN__VIS_SLIVER_NEAR ? (from_b ? db / da : da / db) : 0;
    while (split < 3 && 2 * ratio > (double)(1 << split))
        split++;
    for (size_t q = 0; q < nocc; q++) {
        on[q] = g->fnc[occ[q]];
        memcpy(ov + 12 * q, g->fv + 12 * occ[q], 3 * on[q] * sizeof(double));
    }
    bn__cull_planes(g, occ, nocc, i, j, from_b ? p->b : p->a, from_b ? p->nb : p->na, cull);
    G = from_b ? bn__ff_blocked_integral(p->b, p->nb, nj, p->a, p->na, ov, on, cull, nocc, g->tol, split,
                                         BN__VIS_RTOL, 1e-3 * BN__VIS_RTOL * I, &qs)
               : bn__ff_blocked_integral(p->a, p->na, ni, p->b, p->nb, ov, on, cull, nocc, g->tol, split,
                                         BN__VIS_RTOL, 1e-3 * BN__VIS_RTOL * I, &qs);
    cnt->evals += qs.evals;
    /* the visible part of P is a part of P; where no point saw any of it, the rules' integral of
     * it is 0 exactly (I - G would be the rules' error on the unoccluded kernel instead) */
    return qs.seen ? bn_clamp(I - G, 0, I) : 0;
}

/* Does a face in the shaft (occ[0 .. nocc)) hide pair p wholly, or several faces of one convex
 * solid together (a floor patch behind a block's edge, or under the block, seen from a wall)? Each
 * solid in the list once, not one the pair is on. */
static int bn__pair_hidden(const bn__ffg *g, const bn__pair *p, const size_t *occ, size_t nocc, size_t i, size_t j)
{
    size_t si = bn__solid_of(g->solids, g->patch[i].face), sj = bn__solid_of(g->solids, g->patch[j].face);
    for (size_t q = 0; q < nocc; q++)
        if (bn__face_blocks_all(g, occ[q], p))
            return 1;
    for (size_t q = 0; q < nocc; q++) {
        size_t k = bn__solid_of(g->solids, occ[q]), r = 0;
        if (k == SIZE_MAX || k == si || k == sj)
            continue;
        while (r < q && bn__solid_of(g->solids, occ[r]) != k)
            r++;
        if (r == q && bn__solid_blocks_all(g->solids, k, p->a, p->na, p->b, p->nb, g->tol))
            return 1;
    }
    return 0;
}

/* The visible fraction of pair p by shadow rays between stratified kernel points, in [0, 1] by
 * construction: vis = sum_k F(x_k -> b) V_k / sum_k F(x_k -> b), a ratio of two means, but of
 * bounded, smooth weights (F(x -> b) varies slowly over a and the x_k are stratified), so its O(1/S)
 * bias is far below the noise. */
static double bn__ray_visible(const bn_rt *rt, const bn__ffg *g, const bn_formfactor_opts *o, const bn__pair *p,
                              size_t i, size_t j, bn__scratch *s, bn__counts *cnt)
{
    const double *ni = g->patch[i].normal, *nj = g->patch[j].normal;
    bn__rng r = bn__rng_make(o->seed, i, j);
    double sw = 0, sv = 0;
    bn__kernel_points(&r, p, ni, nj, s);
    cnt->rays += bn__pair_rays(rt, g, ni, nj, s);
    cnt->pairs_tested++;
    for (size_t k = 0; k < s->S; k++) {
        sw += s->w[k];
        if (!s->blocked[k])
            sv += s->w[k];
    }
    return sw > 0 ? sv / sw : 1;
}

/* Monte Carlo point pairs with Wallace's disk regulariser: each sample is the form factor of a
 * disk of area max(Aa, Ab)/S, bounded where the 1/r^2 kernel is not; shadow rays when `maybe`. */
static double bn__mc_pair(const bn_rt *rt, const bn__ffg *g, const bn_formfactor_opts *o, const bn__pair *p,
                          size_t i, size_t j, int maybe, bn__scratch *s, bn__counts *cnt)
{
    const double *ni = g->patch[i].normal, *nj = g->patch[j].normal;
    bn__rng r = bn__rng_make(o->seed, i, j);
    double a_reg = fmax(p->Aa, p->Ab) / (double)s->S, sum = 0;
    int any_blocked = 0;
    bn__pair_points(&r, p, s);
    for (size_t k = 0; k < s->S; k++) {
        double d[3], r2, ci, cj;
        bn_v3_sub(s->y + 3 * k, s->x + 3 * k, d);
        r2 = bn_v3_dot(d, d);
        ci = bn_v3_dot(ni, d);
        cj = -bn_v3_dot(nj, d);
        s->w[k] = ci > 0 && cj > 0 && r2 > 0 ? (ci * cj / r2) / (BN_PI * r2 + a_reg) : 0;
        s->blocked[k] = 0;
    }
    if (maybe) {
        cnt->rays += bn__pair_rays(rt, g, ni, nj, s);
        cnt->pairs_tested++;
    }
    for (size_t k = 0; k < s->S; k++) {
        if (!s->blocked[k])
            sum += s->w[k];
        else
            any_blocked = 1;
    }
    if (any_blocked)
        cnt->pairs_blocked++;
    return p->Aa * p->Ab * sum / (double)s->S;
}

/* A_i F_ij = A_j F_ji of the pair i < j, with visibility; 0 when they cannot see each other.
 * cand: the faces that may occlude (row i's candidates), or NULL: always cast the rays. */
static double bn__pair_value(const bn_rt *rt, const bn__ffg *g, const bn_formfactor_opts *o, double rtol,
                             const size_t *cand, size_t ncand, size_t i, size_t j, bn__scratch *s, bn__counts *cnt)
{
    bn__pair p;
    const double *ni = g->patch[i].normal;
    double I = 0, vis = 1;
    size_t occ[BN__VIS_OCC_MAX + 1], nocc = SIZE_MAX;
    int maybe;
    bn__quad_stats qs;
    if (!bn__pair_prep(g, i, j, &p))
        return 0;
    cnt->pairs_nonzero++;
    if (cand)
        nocc = o->method == BN_FF_ANALYTIC && o->exact_visibility
                   ? bn__shaft_faces(g, cand, ncand, i, j, &p, occ, BN__VIS_OCC_MAX + 1)
                   : bn__shaft_faces(g, cand, ncand, i, j, &p, occ, 1);
    maybe = nocc > 0;
    if (!maybe)
        cnt->pairs_culled++;
    if (o->method != BN_FF_ANALYTIC)
        return bn__mc_pair(rt, g, o, &p, i, j, maybe, s, cnt);
    /* A_i F_ij to relative rtol; the absolute floor keeps F errors below 1e-6 rtol. */
    I = o->quadrature_only
            ? bn__ff_polygon_integral(p.a, p.na, ni, p.b, p.nb, rtol, 1e-6 * rtol * fmin(p.Aa, p.Ab), &qs)
            : bn__ff_unoccluded(p.a, p.na, ni, p.b, p.nb, rtol, 1e-6 * rtol * fmin(p.Aa, p.Ab), &qs);
    cnt->evals += qs.evals;
    /* a face found in the shaft (the first only, with rays) that hides the pair wholly, or a convex
     * solid: 0, with no ray cast and nothing integrated (Cornell box: 55,000 of the 187,000 tested
     * pairs with rays, 29% of the rays; 87,000 with the exact visible part) */
    if (maybe && nocc != SIZE_MAX && bn__pair_hidden(g, &p, occ, nocc, i, j)) {
        vis = 0;
        cnt->pairs_tested++;
        cnt->pairs_exact++;
        cnt->pairs_blocked++;
    } else if (maybe && nocc <= BN__VIS_OCC_MAX && o->exact_visibility) {
        double V = bn__exact_visible(g, I, i, j, &p, occ, nocc, cnt);
        cnt->pairs_tested++;
        cnt->pairs_exact++;
        if (V < I)
            cnt->pairs_blocked++;
        I = V;
    } else if (maybe) {
        vis = bn__ray_visible(rt, g, o, &p, i, j, s, cnt);
        if (vis < 1)
            cnt->pairs_blocked++;
    }
    return I * vis;
}

static void bn__analytic_or_mc_pair(const bn_rt *rt, const bn__ffg *g, const bn_formfactor_opts *o, double rtol,
                                    const size_t *cand, size_t ncand, size_t i, size_t j, bn__scratch *s,
                                    bn__sink *sink, bn__counts *cnt)
{
    double I = bn__pair_value(rt, g, o, rtol, cand, ncand, i, j, s, cnt);
    if (I == 0)
        return;   /* exactly 0: F is zeroed storage */
    /* reciprocity: A_i F_ij = A_j F_ji = I */
    bn__sink_put(sink, i, j, I / g->patch[i].area);
    bn__sink_put(sink, j, i, I / g->patch[j].area);
}

static void bn__frame(const double n[3], double t[3], double b[3])
{
    double a[3] = {0, 0, 0};
    a[fabs(n[0]) < 0.6 ? 0 : (fabs(n[1]) < 0.6 ? 1 : 2)] = 1;
    bn_v3_cross(n, a, t);
    bn_v3_normalize(t);
    bn_v3_cross(n, t, b);
}

static void bn__hemisphere_row(const bn_rt *rt, const bn__ffg *g, const bn_formfactor_opts *o, size_t i,
                               bn__scratch *s, bn__sink *sink, bn__counts *cnt)
{
    const bn_patch *pa = &g->patch[i];
    const double *n = pa->normal;
    double t[3], b[3], inv = 1.0 / (double)s->S;
    bn__rng r = bn__rng_make(o->seed, i, 0x68656d69ULL);
    bn__frame(n, t, b);
    bn__perms(&r, s->perm, s->S);
    for (size_t k = 0; k < s->S; k++) {
        double u1 = ((double)k + bn__rng_uniform(&r)) * inv, v1 = ((double)s->perm[k] + bn__rng_uniform(&r)) * inv;
        double u2 = ((double)s->perm[s->S + k] + bn__rng_uniform(&r)) * inv;
        double v2 = ((double)s->perm[2 * s->S + k] + bn__rng_uniform(&r)) * inv;
        double x[3], d[3];
        bn_hit h;
        bn__poly_sample(bn__pc(g, i), pa->ncorners, u1, v1, x);
        bn_v3_cosine_dir(n, t, b, u2, v2, d);
        bn_v3_madd(x, g->eps, n, x);
        if (bn_rt_intersect(rt, x, d, 0, INFINITY, &h) && h.front && h.patch != i)
            s->row[h.patch] += 1;
    }
    cnt->rays += s->S;
    for (size_t j = 0; j < g->n; j++)
        if (s->row[j] > 0) {
            bn__sink_put(sink, i, j, s->row[j] * inv);
            s->row[j] = 0;
        }
}

/* Faces partly in front of patch i: the only possible occluders of its pairs. */
static size_t bn__row_candidates(const bn__ffg *g, size_t i, size_t *cand)
{
    size_t m = 0;
    for (size_t f = 0; f < g->nf; f++) {
        if (f == g->patch[i].face)
            continue;
        if (bn__max_height(g->fv + 12 * f, g->fnc[f], g->patch[i].normal, bn__pc(g, i)) > g->tol)
            cand[m++] = f;
    }
    return m;
}

/* ---- memory ---- */

static size_t bn__limit(const bn_formfactor_opts *o)
{
    return o->max_memory ? o->max_memory : bn_memory_limit_default();
}

static void bn__gib(double b, char *buf, size_t n)
{
    const char *u[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
    int k = 0;
    while (b >= 1024 && k < 6) {
        b /= 1024;
        k++;
    }
    snprintf(buf, n, "%.3g %s", b, u[k]);
}

/* Per-thread buffers of the assembly and the per-patch geometry, beside F itself. */
static size_t bn__scratch_bytes(size_t S, size_t n, int threads)
{
    return (size_t)threads * (S * (3 * sizeof(unsigned) + 7 * sizeof(double) + 7 * sizeof(float) + 1) + n * 8) +
           n * 64;
}

static size_t bn__work_bytes(const bn_formfactor_opts *o, size_t n)
{
    return bn__scratch_bytes((size_t)bn__samples(o), o->method == BN_FF_HEMISPHERE ? n : 0, bn_threads_resolve(o->threads));
}

size_t bn_formfactor_bytes_needed(const bn_scene *scene, const bn_formfactor_opts *o)
{
    size_t n, nnz = 0, need;
    bn_scene_patches(scene, &n);
    if (bn_storage_needs_pattern(o->storage)) {
        bn__ffg g;
        if (bn__ffg_init(&g, scene, 0, NULL) != BN_OK)
            return SIZE_MAX;
        for (size_t i = 0; i < n; i++)
            nnz += bn__facing_cols(&g, i, NULL);
        bn__ffg_free(&g);
    }
    need = bn_storage_bytes(o->storage, n, nnz, o->precision);
    return need == SIZE_MAX ? need : need + bn__work_bytes(o, n);
}

static bn_status bn__memory_error(size_t n, size_t need, size_t limit, const bn_formfactor_opts *o, bn_error *err)
{
    char a[32], b[32], c[32];
    double ratio = need == SIZE_MAX ? 1e30 : (double)need / (double)limit;
    size_t dense = bn_storage_bytes("dense", n, 0, o->precision);
    char smaller[96];
    bn_storage_smaller(o->storage, o->precision, smaller, sizeof smaller);
    bn__gib(need == SIZE_MAX ? 1.8e19 : (double)need, a, sizeof a);
    bn__gib((double)limit, b, sizeof b);
    bn__gib(dense == SIZE_MAX ? 1.8e19 : (double)dense, c, sizeof c);
    return bn_error_set(err, BN_ENOMEM,
                        "%s F for %zu patches needs %s (dense N^2 alone is %s), above the limit of %s (`max_memory`%s). "
                        "Remedies: a coarser mesh (about %zu patches would fit: raise `patch_size` by %.2gx or lower "
                        "`patches`)%s, or raise `max_memory`",
                        o->storage, n, a, c, b, o->max_memory ? "" : "; default 80% of physical memory",
                        (size_t)((double)n / sqrt(ratio) * 0.95), sqrt(sqrt(ratio)) * 1.05,
                        smaller);
}

bn_status bn_formfactor_check_memory(double n_estimate, const bn_formfactor_opts *o, bn_error *err)
{
    size_t n, need, limit = bn__limit(o);
    if (bn_storage_needs_pattern(o->storage))
        return BN_OK;   /* its size depends on which pairs face each other: known only after meshing */
    n = n_estimate >= 1e18 ? (size_t)1e18 : (size_t)n_estimate;
    need = bn_storage_bytes(o->storage, n, 0, o->precision);
    if (need != SIZE_MAX)
        need = need + bn__work_bytes(o, n) < need ? SIZE_MAX : need + bn__work_bytes(o, n);
    if (need == SIZE_MAX || need > limit)
        return bn__memory_error(n, need, limit, o, err);
    return BN_OK;
}

/* ---- diagnostics over the stored F (through the operator: any storage) ---- */

/* The first entry outside [0, 1] (or not finite), with its patches and faces. */
static bn_status bn__bad_entry(const bn_scene *scene, const bn_ff_diagnostics *d, size_t i, size_t j, double v,
                               const bn_formfactor_opts *o, bn_error *err)
{
    size_t np, nf;
    const bn_patch *patch = bn_scene_patches(scene, &np);
    const bn_face *faces = bn_scene_faces(scene, &nf);
    return bn_error_set(err, BN_ENUMERIC,
                        "F[%zu][%zu] = %.9g between patch %zu (face %zu, line %u) and patch %zu (face %zu, line "
                        "%u) is outside [0, 1] or not finite (%zu negative, %zu above 1 or non-finite entries; "
                        "method %s): refusing to use it",
                        i, j, v, i, patch[i].face, faces[patch[i].face].line, j, patch[j].face,
                        faces[patch[j].face].line, d->negative_entries, d->above_one_entries,
                        bn_ff_method_name(o->method));
}

/* Row sums, entry ranges, reciprocity A_i F_ij = A_j F_ji and ||K||_inf of the stored F; refuses
 * entries outside [0, 1] and rows summing far above 1 (bn__rowsum_error). */
/* The diagnostics' running state over the rows: the first bad entry, the reciprocity residual. */
typedef struct bn__diag_scan {
    size_t bad_i, bad_j, worst_row;
    double bad_v, rec, sum_dev2;
} bn__diag_scan;

/* Entry (i, j) = v of row i: counted (nonzero, negative, above 1 or not finite; the first bad one kept)
 * and, for a stored pair once (j > i), its reciprocity against (j, i); a mirror that is 0 is a broken pair. */
static bn_status bn__diag_entry(const bn_transport *k, const bn_patch *patch, size_t i, size_t j, double v,
                                bn_ff_diagnostics *d, bn__diag_scan *S, bn_error *err)
{
    double w;
    int bad = 0;
    bn_status st;
    if (v != 0)
        d->nonzeros++;
    if (!isfinite(v))
        bad = 1, d->above_one_entries++;
    else if (v < 0)
        bad = 1, d->negative_entries++;
    else if (v > 1 + BN__F_SLACK)
        bad = 1, d->above_one_entries++;
    if (bad && S->bad_i == SIZE_MAX) {
        S->bad_i = i;
        S->bad_j = j;
        S->bad_v = v;
    }
    if (v == 0 || j == i)
        return BN_OK;
    st = bn_transport_entry(k, j, i, &w, err);
    if (st == BN_OK && j > i) {
        double a = patch[i].area * v, c = patch[j].area * w, m = fmax(fabs(a), fabs(c));
        if (m > 0)
            S->rec = fmax(S->rec, fabs(a - c) / m);
    } else if (st == BN_OK && w == 0) {
        S->rec = 1;
    }
    return st;
}

/* Row i's sum rs into the row statistics and ||K||_inf. */
static void bn__diag_row(const double *rho, size_t i, double rs, bn_ff_diagnostics *d, bn__diag_scan *S)
{
    d->row_sum_min = fmin(d->row_sum_min, rs);
    if (rs > d->row_sum_max)
        S->worst_row = i;
    d->row_sum_max = fmax(d->row_sum_max, rs);
    S->sum_dev2 += (rs - 1) * (rs - 1);
    if (rs > 1 + d->row_sum_tol)
        d->rows_above_one++;
    for (int c = 0; c < 3; c++)
        d->k_norm_inf = fmax(d->k_norm_inf, rho[3 * i + c] * rs);
}

static bn_status bn__diagnose(const bn_scene *scene, const bn_transport *k, const bn_formfactor_opts *o,
                              bn_ff_diagnostics *d, bn_error *err)
{
    size_t n = bn_transport_size(k), np, cnt;
    const bn_patch *patch = bn_scene_patches(scene, &np);
    const double *rho = bn_transport_rho(k);
    size_t *cols = bn__malloc_array(n ? n : 1, sizeof(size_t));
    double *vals = bn__malloc_array(n ? n : 1, sizeof(double));
    bn__diag_scan S = {SIZE_MAX, 0, 0, 0, 0, 0};
    bn_status st = (cols && vals) ? BN_OK : bn_error_set(err, BN_ENOMEM, "out of memory");
    d->n = n;
    d->row_sum_min = n ? INFINITY : 0;
    d->row_sum_max = n ? -INFINITY : 0;
    d->negative_entries = d->above_one_entries = d->rows_above_one = d->nonzeros = 0;
    d->k_norm_inf = 0;
    for (size_t i = 0; i < n && st == BN_OK; i++) {
        double rs = 0;
        st = bn_transport_row_entries(k, i, cols, vals, &cnt, err);
        for (size_t q = 0; q < cnt && st == BN_OK; q++) {
            rs += vals[q];
            st = bn__diag_entry(k, patch, i, cols[q], vals[q], d, &S, err);
        }
        bn__diag_row(rho, i, rs, d, &S);
    }
    free(cols);
    free(vals);
    if (st != BN_OK)
        return st;
    d->row_sum_rms_dev = n ? sqrt(S.sum_dev2 / (double)n) : 0;
    d->reciprocity_residual = S.rec;
    if (S.bad_i != SIZE_MAX)
        return bn__bad_entry(scene, d, S.bad_i, S.bad_j, S.bad_v, o, err);
    if ((o->method == BN_FF_HEMISPHERE && d->row_sum_max > 1 + d->row_sum_tol) ||
        (o->method == BN_FF_ANALYTIC && d->row_sum_max > 1 + BN__ROWSUM_ERROR))
        return bn_error_set(err, BN_ENUMERIC,
                            "row %zu of F (patch %zu, face %zu) sums to %.9g, above 1 + %.3g (method %s): the form "
                            "factors are wrong; refusing to use them",
                            S.worst_row, S.worst_row, patch[S.worst_row].face, d->row_sum_max,
                            o->method == BN_FF_HEMISPHERE ? d->row_sum_tol : BN__ROWSUM_ERROR,
                            bn_ff_method_name(o->method));
    return BN_OK;
}

static double bn__rowsum_tol(const bn_formfactor_opts *o)
{
    /* the stored values' rounding over a row (16 entries' worth: 1e-6 in float), and never below
     * 1e-12: double sums of many hemisphere fractions k/S carry that much */
    double round = fmax(16 * bn_precision_epsilon(o->precision), 1e-12);
    if (o->method == BN_FF_ANALYTIC)   /* quadrature, and the visible parts' integration (or sampling) */
        return 10 * (o->tolerance > 0 ? o->tolerance : BN_FF_TOLERANCE_DEFAULT) + round +
               (o->exact_visibility ? BN__VIS_ROW_ALLOWANCE : 0);
    if (o->method == BN_FF_HEMISPHERE)
        return round;
    return 3.0 / sqrt((double)bn__samples(o));   /* montecarlo: statistical */
}

/* ---- the stages of the assembly ---- */

/* The cache key: everything that changes F (the scene's geometry and meshing through their digest,
 * not its materials: the file holds F, and K = diag(rho) F is made with the scene's rho on reading;
 * the options). The seed
 * is part of it only when the assembly drew random samples (Monte Carlo pairs, hemisphere rays, the
 * closed form's shadow rays): `seeded` 0 writes "seed=unused", which any seed's lookup accepts. */
static void bn__cache_key(const bn_scene *scene, const bn_formfactor_opts *o, size_t n, int seeded, char *key,
                          size_t size)
{
    char desc[400], *at;
    bn_formfactor_opts_describe(o, desc, sizeof desc);
    at = strstr(desc, " seed=");
    if (!seeded && at) {
        char rest[400];
        const char *after = strchr(at + 1, ' ');
        snprintf(rest, sizeof rest, "%s", after ? after : "");
        snprintf(at, sizeof desc - (size_t)(at - desc), " seed=unused%s", rest);
    }
    snprintf(key, size, "bounce-ff-cache v3 bounce=%s geometry=%016llx patches=%zu %s", bn_version(),
             (unsigned long long)bn_scene_geometry_digest(scene), n, desc);
}

/* The storage's builder, refused with the remedies when F and the work buffers exceed the limit. */
static bn_status bn__open_builder(const bn_scene *scene, bn__ffg *g, const bn_formfactor_opts *o, size_t n,
                                  bn__sink **out, bn_error *err)
{
    bn_builder_opts bo;
    size_t limit = bn__limit(o), work = bn__work_bytes(o, n), need = 0;
    bn_status st;
    (void)scene;
    bn_builder_opts_default(&bo);
    bo.storage = o->storage;
    bo.precision = o->precision;
    bo.drop_below = o->sparse_threshold;
    bo.max_bytes = limit > work ? limit - work : 1;
    bo.pattern = bn__facing_cols;
    bo.pattern_user = g;
    st = bn_transport_builder_create(n, &bo, &need, out, err);
    if (st == BN_ENOMEM && (need == SIZE_MAX || need > bo.max_bytes))
        return bn__memory_error(n, need == SIZE_MAX ? need : need + work, limit, o, err);
    return st;
}

/* Every pair (or every row, for hemisphere) into the builder; counts into *tot. Rows are dealt
 * cyclically to balance the triangle i < j; every pair is computed from its own seed, so the result
 * does not depend on the schedule or the thread count. */
static bn_status bn__assemble(const bn_rt *rt, const bn__ffg *g, const bn_formfactor_opts *o, bn__sink *sink,
                              bn__counts *tot, bn_error *err)
{
    size_t n = g->n, S = (size_t)bn__samples(o), done = 0;
    volatile int fail = 0;
    bn__progress prog;
    bn__progress_begin(&prog, "form factors", o->method == BN_FF_HEMISPHERE ? n : n * (n - 1) / 2, o->quiet);
#pragma omp parallel
    {
        bn__scratch s;
        bn__counts c;
        size_t *cand = bn__malloc_array(g->nf ? g->nf : 1, sizeof(size_t));
        long ln = (long)n;
        memset(&c, 0, sizeof c);
        if (!bn__scratch_init(&s, S, o->method == BN_FF_HEMISPHERE ? n : 0) || !cand)
            fail = 1;
#pragma omp for schedule(static, 1)
        for (long li = 0; li < ln; li++) {
            size_t i = (size_t)li, work;
            if (fail || bn_interrupted() != BN_OK)
                continue;
            if (o->method == BN_FF_HEMISPHERE) {
                bn__hemisphere_row(rt, g, o, i, &s, sink, &c);
                work = 1;
            } else {
                size_t ncand = bn__row_candidates(g, i, cand);
                for (size_t j = i + 1; j < n; j++)
                    bn__analytic_or_mc_pair(rt, g, o, o->tolerance, cand, ncand, i, j, &s, sink, &c);
                work = n - 1 - i;
            }
            bn__progress_step(&prog, &done, work);
        }
#pragma omp critical(bn_ff_counts)
        {
            tot->pairs_nonzero += c.pairs_nonzero;
            tot->pairs_culled += c.pairs_culled;
            tot->pairs_tested += c.pairs_tested;
            tot->pairs_blocked += c.pairs_blocked;
            tot->pairs_exact += c.pairs_exact;
            tot->rays += c.rays;
            tot->evals += c.evals;
        }
        bn__scratch_free(&s);
        free(cand);
    }
    bn__progress_end(&prog);
    if (fail)
        return bn_error_set(err, BN_ENOMEM, "out of memory for per-thread buffers (%zu samples)", S);
    if (bn_interrupted() != BN_OK)
        return bn_error_set(err, bn_interrupted(), "form-factor assembly interrupted");
    return BN_OK;
}

/* K = diag(rho) F from the filled builder, with the assembly's counts in the diagnostics. */
static bn_status bn__finish(const bn_scene *scene, size_t n, bn__sink *sink, const bn__counts *tot,
                            const bn_formfactor_opts *o, bn_transport **out, bn_ff_diagnostics *d, bn_error *err)
{
    bn_builder_report rep;
    bn_status st;
    double *rho = bn__malloc_array(3 * (n ? n : 1), sizeof(double));
    if (!rho) {
        bn_transport_builder_destroy(sink);
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    }
    bn_scene_patch_reflectance(scene, rho);
    st = bn_transport_builder_finish(sink, rho, out, &rep, err);
    free(rho);
    if (st != BN_OK)
        return st;
    d->dropped_entries = rep.dropped_entries;
    d->dropped_mass_max = rep.dropped_mass_max;
    d->pairs_nonzero = tot->pairs_nonzero;
    d->pairs_culled = tot->pairs_culled;
    d->pairs_tested = tot->pairs_tested;
    d->pairs_blocked = tot->pairs_blocked;
    d->pairs_exact = tot->pairs_exact;
    d->rays = tot->rays;
    d->quad_evals = tot->evals;
    d->occluded_fraction = tot->pairs_nonzero ? (double)tot->pairs_blocked / (double)tot->pairs_nonzero : 0;
    if (rep.lost_puts)
        bn_warnf(&o->log, BN_W_PATTERN, (double)rep.lost_puts, "%zu hemisphere hits landed on patches outside the sparse pattern (grazing)",
                rep.lost_puts);
    return BN_OK;
}

static void bn__warn_rows(const bn_formfactor_opts *o, const bn_ff_diagnostics *d)
{
    if (d->rows_above_one)
        bn_warnf(&o->log, BN_W_ROW_SUM, d->row_sum_max, "%zu rows of F sum to more than 1 + %.3g (largest %.9g; method %s)%s",
                d->rows_above_one, d->row_sum_tol, d->row_sum_max, bn_ff_method_name(o->method),
                o->method == BN_FF_HEMISPHERE ? ""
                : o->method == BN_FF_ANALYTIC && o->exact_visibility && d->pairs_exact == d->pairs_tested
                    ? ": the integration of the exactly visible parts over the patches (shadows crease it)"
                    : ": sampling noise of the visibility estimate; more `samples` reduce it");
}

/* A cache hit: K read through the storage's builder, checked like a fresh assembly. *hit = 0 on
 * a miss (said as a note), which is not an error. */
static bn_status bn__from_cache(const bn_scene *scene, const bn_formfactor_opts *o, const char *key,
                                const char *alt, bn_transport **out, bn_ff_diagnostics *d, int *hit, bn_error *err)
{
    char why[256];
    bn_status st;
    size_t n;
    double *rho;
    bn_scene_patches(scene, &n);
    *hit = 0;
    why[0] = '\0';
    rho = bn__malloc_array(3 * (n ? n : 1), sizeof(double));
    if (!rho)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    bn_scene_patch_reflectance(scene, rho);
    st = bn__ff_read_cache(o->cache_path, key, alt, n, o->storage, o->precision, rho, out, why, sizeof why);
    free(rho);
    if (st != BN_OK) {
        if (why[0])
            bn_logf(&o->log, BN_LOG_INFO, "cache %s not used: %s", o->cache_path, why);
        return BN_OK;   /* a miss: assemble and overwrite */
    }
    st = bn__diagnose(scene, *out, o, d, err);
    if (st != BN_OK) {
        bn_transport_destroy(*out);
        *out = NULL;
        return st;
    }
    d->bytes = bn_transport_bytes(*out);
    d->from_cache = 1;
    *hit = 1;
    bn_logf(&o->log, BN_LOG_INFO, "form factors read from cache %s", o->cache_path);
    return BN_OK;
}

/* ---- the public entry ---- */

/* Options as the assembly uses them: defaults filled, and checked. */
static bn_status bn__ff_opts(const bn_scene *scene, const bn_rt *rt, const bn_formfactor_opts *in,
                             bn_formfactor_opts *o, bn_error *err)
{
    size_t n;
    *o = *in;
    if (o->tolerance <= 0)
        o->tolerance = BN_FF_TOLERANCE_DEFAULT;
    if (!o->storage)
        o->storage = BN_STORAGE_DEFAULT;
    bn_scene_patches(scene, &n);
    if (n == 0)
        return bn_error_set(err, BN_EINPUT, "%s: no patches (mesh the scene first)", bn_scene_path(scene));
    if (rt && bn_rt_scene(rt) != scene)
        return bn_error_set(err, BN_EINTERNAL, "bn_formfactor_build: rt was built for another scene");
    if (!bn_storage_exists(o->storage))
        return bn_error_set(err, BN_EUSAGE, "unknown storage '%s' (one of %s)", o->storage, bn_storage_names());
    if (!(o->sparse_threshold >= 0 && o->sparse_threshold < 1))
        return bn_error_set(err, BN_EINPUT, "sparse threshold %g is outside [0, 1)", o->sparse_threshold);
    return BN_OK;
}

static bn_status bn__formfactor_build_body(const bn_scene *scene, const bn_rt *rt, const bn_formfactor_opts *o_in,
                              bn_transport **out, bn_ff_diagnostics *diag, bn_error *err)
{
    bn_formfactor_opts o;
    bn_ff_diagnostics dlocal, *d = diag ? diag : &dlocal;
    bn__ffg g;
    bn__sink *sink = NULL;
    bn__counts tot;
    char key[512], unseeded[512];
    double t0 = bn__now();
    size_t n;
    int hit = 0;
    bn_status st;

    *out = NULL;
    memset(d, 0, sizeof *d);
    memset(&tot, 0, sizeof tot);
    st = bn__ff_opts(scene, rt, o_in, &o, err);
    if (st != BN_OK)
        return st;
    bn_scene_patches(scene, &n);
    d->method = o.method;
    d->samples = bn__samples(&o);
    d->row_sum_tol = bn__rowsum_tol(&o);
    bn__cache_key(scene, &o, n, 1, key, sizeof key);
    bn__cache_key(scene, &o, n, 0, unseeded, sizeof unseeded);
    if (o.cache_path) {
        st = bn__from_cache(scene, &o, key, unseeded, out, d, &hit, err);
        d->seconds = bn__now() - t0;
        if (st != BN_OK || hit)
            return st;
    }
    if (!rt)
        return bn_error_set(err, BN_EINTERNAL, "bn_formfactor_build: no ray-casting structure (and no cache hit)");

    st = bn__ffg_init(&g, scene, bn_rt_epsilon(rt), err);
    if (st != BN_OK)
        return st;
    st = bn__open_builder(scene, &g, &o, n, &sink, err);
    if (st == BN_OK) {
        st = bn__assemble(rt, &g, &o, sink, &tot, err);
        if (st != BN_OK)
            bn_transport_builder_destroy(sink);
    }
    bn__ffg_free(&g);
    if (st == BN_OK)
        st = bn__finish(scene, n, sink, &tot, &o, out, d, err);
    if (st == BN_OK)
        st = bn__diagnose(scene, *out, &o, d, err);
    if (st != BN_OK) {
        bn_transport_destroy(*out);
        *out = NULL;
        return st;
    }
    bn__warn_rows(&o, d);
    d->bytes = bn_transport_bytes(*out);
    d->seconds = bn__now() - t0;
    d->rays_per_second = d->seconds > 0 ? (double)d->rays / d->seconds : 0;
    if (o.cache_path) {
        bn_error cerr;
        bn_error_clear(&cerr);
        int seeded = o.method != BN_FF_ANALYTIC || d->rays > 0;   /* the closed form with exact visibility: no draws */
        if (bn__ff_write_file(*out, scene, o.cache_path, seeded ? key : unseeded, NULL, o.precision, o.storage,
                              &cerr) != BN_OK)
            bn_warnf(&o.log, BN_W_CACHE, NAN, "cannot write the form-factor cache: %s", cerr.msg);
    }
    return BN_OK;
}

bn_status bn_formfactor_build(const bn_scene *scene, const bn_rt *rt, const bn_formfactor_opts *o,
                              bn_transport **out, bn_ff_diagnostics *diag, bn_error *err)
{
    int prev = bn__threads_begin(o->threads);
    bn_status st = bn__formfactor_build_body(scene, rt, o, out, diag, err);
    bn__threads_end(prev);
    return st;
}

double bn_ff_point_to_polygon(const double x[3], const double n[3], const double *v, size_t nv)
{
    double *c = bn__malloc_array(3 * (nv + 1), sizeof(double));
    size_t m;
    double f;
    if (!c)
        return NAN;
    m = bn__poly_clip(v, nv, n, x, 0, c);
    f = m ? bn__ff_point_polygon(x, n, c, m) : 0;
    free(c);
    return f;
}

double bn_ff_polygon_pair(const double *vi, size_t ni, const double *vj, size_t nj, double rtol)
{
    double nni[3], nnj[3], Ai, *a, *b, f = 0, diam = 0;
    size_t na, nb;
    Ai = bn__poly_area(vi, ni, nni);
    bn__poly_area(vj, nj, nnj);
    if (!(Ai > 0) || ni < 3 || nj < 3)
        return 0;
    for (size_t k = 0; k < ni; k++)
        for (size_t m = 0; m < nj; m++)
            diam = fmax(diam, bn_v3_dist(vi + 3 * k, vj + 3 * m));
    a = bn__malloc_array(3 * (ni + 1), sizeof(double));
    b = bn__malloc_array(3 * (nj + 1), sizeof(double));
    if (!a || !b) {
        free(a);
        free(b);
        return NAN;
    }
    /* the part of i in front of j and of j in front of i */
    na = bn__max_height(vj, nj, nni, vi) > 1e-12 * diam ? bn__poly_clip(vi, ni, nnj, vj, 1e-12 * diam, a) : 0;
    nb = na && bn__max_height(vi, ni, nnj, vj) > 1e-12 * diam ? bn__poly_clip(vj, nj, nni, vi, 1e-12 * diam, b) : 0;
    if (na && nb)
        f = bn__ff_unoccluded(a, na, nni, b, nb, rtol > 0 ? rtol : BN_FF_TOLERANCE_DEFAULT, 0, NULL) / Ai;
    free(a);
    free(b);
    return f;
}

void bn_ff_diagnostics_print(const bn_ff_diagnostics *d, FILE *fp)
{
    fprintf(fp, "patches              %zu\n", d->n);
    fprintf(fp, "method               %s (%d samples)%s\n", bn_ff_method_name(d->method), d->samples,
            d->from_cache ? ", read from the cache" : "");
    fprintf(fp, "row sums             min %.9f  max %.9f  RMS(sum - 1) %.3g\n", d->row_sum_min, d->row_sum_max,
            d->row_sum_rms_dev);
    fprintf(fp, "rows above 1         %zu (allowance %.3g)\n", d->rows_above_one, d->row_sum_tol);
    fprintf(fp, "reciprocity          max |A_i F_ij - A_j F_ji| / max = %.3g\n", d->reciprocity_residual);
    fprintf(fp, "entries              %zu nonzero; %zu negative; %zu above 1 or not finite\n", d->nonzeros,
            d->negative_entries, d->above_one_entries);
    if (!d->from_cache) {
        fprintf(fp, "pairs                %zu facing; %zu shaft-culled (no rays); %zu tested (%zu exactly, %zu by rays); "
                    "%zu partly blocked (occluded fraction %.4f)\n",
                d->pairs_nonzero, d->pairs_culled, d->pairs_tested, d->pairs_exact, d->pairs_tested - d->pairs_exact,
                d->pairs_blocked, d->occluded_fraction);
        fprintf(fp, "rays                 %zu (%.3g rays/s)\n", d->rays, d->rays_per_second);
        if (d->quad_evals)
            fprintf(fp, "kernel evaluations   %zu\n", d->quad_evals);
    }
    if (d->dropped_entries)
        fprintf(fp, "sparse threshold     %zu entries dropped; largest dropped mass per row %.3g\n",
                d->dropped_entries, d->dropped_mass_max);
    fprintf(fp, "||K||_inf            %.9f (max_i rho_i sum_j F_ij)\n", d->k_norm_inf);
    fprintf(fp, "bytes                %zu\n", d->bytes);
    fprintf(fp, "seconds              %.3f\n", d->seconds);
}

/* ---- one pair at a time, for operators that choose their own pairs (src/formfactor/ff_pair.h) ---- */

struct bn__ff_pairs {
    bn__ffg g;
    const bn_rt *rt;
    bn_formfactor_opts o;
};

struct bn__ff_worker {
    bn__scratch s;
    size_t cap;          /* samples the scratch holds */
    size_t *cand;
    size_t cand_row;     /* the row cand holds (SIZE_MAX: none) */
    size_t ncand;
    bn__counts c;
};

bn_status bn__ff_pairs_create(const bn_scene *scene, const bn_rt *rt, const bn_formfactor_opts *o,
                              bn__ff_pairs **out, bn_error *err)
{
    bn__ff_pairs *p;
    bn_status st;
    *out = NULL;
    if (o->method == BN_FF_HEMISPHERE)
        return bn_error_set(err, BN_EUSAGE, "hemisphere form factors come a row at a time, not per pair "
                                            "(use `ff_method` analytic or montecarlo)");
    p = bn__calloc(1, sizeof *p);
    if (!p)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    st = bn__ff_opts(scene, rt, o, &p->o, err);
    if (st == BN_OK)
        st = bn__ffg_init(&p->g, scene, bn_rt_epsilon(rt), err);
    if (st != BN_OK) {
        free(p);
        return st;
    }
    p->rt = rt;
    *out = p;
    return BN_OK;
}

void bn__ff_pairs_destroy(bn__ff_pairs *p)
{
    if (!p)
        return;
    bn__ffg_free(&p->g);
    free(p);
}

bn__ff_worker *bn__ff_worker_create(const bn__ff_pairs *p)
{
    bn__ff_worker *w = bn__calloc(1, sizeof *w);
    if (!w)
        return NULL;
    w->cand = bn__malloc_array(p->g.nf ? p->g.nf : 1, sizeof(size_t));
    w->cand_row = SIZE_MAX;
    w->cap = (size_t)bn__samples(&p->o) > BN__FF_QUICK_MAX ? (size_t)bn__samples(&p->o) : BN__FF_QUICK_MAX;
    if (!w->cand || !bn__scratch_init(&w->s, w->cap, 0)) {
        bn__ff_worker_destroy(w);
        return NULL;
    }
    return w;
}

void bn__ff_worker_destroy(bn__ff_worker *w)
{
    if (!w)
        return;
    bn__scratch_free(&w->s);
    free(w->cand);
    free(w);
}

double bn__ff_pair(const bn__ff_pairs *p, bn__ff_worker *w, size_t i, size_t j, int cull)
{
    size_t a = i < j ? i : j, b = i < j ? j : i;
    if (i == j)
        return 0;
    if (cull && w->cand_row != a) {
        w->ncand = bn__row_candidates(&p->g, a, w->cand);
        w->cand_row = a;
    }
    w->s.S = (size_t)bn__samples(&p->o);
    return bn__pair_value(p->rt, &p->g, &p->o, p->o.tolerance, cull ? w->cand : NULL, w->ncand, a, b, &w->s, &w->c);
}

double bn__ff_pair_quick(const bn__ff_pairs *p, bn__ff_worker *w, size_t i, size_t j, int S, double rtol,
                         double ftol, double *sigma, int *first_only)
{
    const bn__ffg *g = &p->g;
    const double *ni = g->patch[i].normal, *nj = g->patch[j].normal;
    bn__pair pp;
    bn__quad_stats qs;
    double I;
    int near;
    *sigma = 0;
    *first_only = 0;
    if (i == j || !bn__pair_prep(g, i, j, &pp))
        return 0;
    if (S < 1)
        S = 1;
    /* the hierarchy's leaf links by the million, to 1e-3: far pairs by the quadrature, the cheaper
     * there (10 kernel evaluations against the contour's 60 panel points), near ones by the contour
     * (the quadrature misses by 1e-3 at a gap of 1e-3 of the side) */
    near = bn__ff_near(pp.a, pp.na, pp.b, pp.nb);
    I = (near ? bn__ff_unoccluded(pp.a, pp.na, ni, pp.b, pp.nb, rtol, 1e-6 * rtol * fmin(pp.Aa, pp.Ab), &qs)
             : bn__ff_polygon_integral(pp.a, pp.na, ni, pp.b, pp.nb, rtol, 1e-6 * rtol * fmin(pp.Aa, pp.Ab), &qs)) /
        g->patch[i].area;
    w->c.evals += qs.evals;
    for (int round = 0; round < 2; round++) {
        size_t n = (size_t)S << (2 * round);
        bn__rng r = bn__rng_make(p->o.seed ^ 0x717569636b6c6e6bull, ((uint64_t)i << 32) ^ j, (uint64_t)round);
        double sw = 0, sv = 0;
        size_t blocked = 0, seen = 0;
        if (n > w->cap)
            n = w->cap;
        w->s.S = n;
        if (near)
            bn__kernel_points(&r, &pp, ni, nj, &w->s);
        else
            bn__area_points(&r, &pp, ni, nj, &w->s);
        w->c.rays += bn__pair_rays(p->rt, g, ni, nj, &w->s);
        for (size_t k = 0; k < n; k++) {
            sw += w->s.w[k];
            seen += w->s.w[k] > 0;
            if (w->s.w[k] > 0 && w->s.blocked[k])
                blocked++;
            else
                sv += w->s.w[k];
        }
        if (round == 0 && blocked > 0 && blocked < seen) {
            if (bn__ff_vis_noise(I, (double)n) > ftol)
                continue;   /* partly visible, and its noise could matter: four times the rays */
            *first_only = 1;
        }
        {
            double v = sw > 0 ? sv / sw : 1;
            *sigma = I * sqrt((v * (1 - v) + 1.0 / (double)n) / (double)n);
            return I * v;
        }
    }
    return 0;
}

size_t bn__ff_worker_rays(const bn__ff_worker *w) { return w->c.rays; }
