/* The solve driver for every method (PETSc's KSPSolve_Richardson + KSPMonitor): checks E and K,
 * estimates ||K||_inf and the spectral radius, refuses (near-)singular systems before iterating,
 * predicts the iteration count, then runs sweep -> residual -> monitor row -> stop test, and
 * finally computes the per-bounce terms K^k E. Equation: (I - K) L = E, K = diag(rho) F.
 * Every norm and sum is in double and serial, so results do not depend on the thread count. */
#include "bounce/solve.h"
#include "solve/solve_internal.h"
#include "base/internal.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <string.h>

/* The methods in enum order (bn_solve_method). */
#define BN__METHODS(X) X("jacobi") X("gauss-seidel") X("neumann") X("direct")
BN__VOCABULARY(bn_solve_method, bn_solve_method, BN__METHODS)

/* The stopping tests in enum order (bn_solve_stop). */
#define BN__STOPS(X) X("default") X("residual") X("bound") X("patch")
BN__VOCABULARY(bn_solve_stop, bn_solve_stop, BN__STOPS)

const char *bn_stop_reason_name(bn_stop_reason r)
{
    switch (r) {
    case BN_STOP_NONE: return "none";
    case BN_STOP_CONVERGED_RTOL: return "converged-rtol";
    case BN_STOP_CONVERGED_ATOL: return "converged-atol";
    case BN_STOP_DIRECT: return "direct";
    case BN_STOP_MAX_ITER: return "iteration-limit";
    case BN_STOP_DIVERGED_NAN: return "diverged-nan";
    case BN_STOP_DIVERGED_GROWTH: return "diverged-growth";
    case BN_STOP_SINGULAR: return "singular";
    }
    return "?";
}

void bn_solve_opts_default(bn_solve_opts *o)
{
    memset(o, 0, sizeof *o);
    o->method = BN_SOLVE_GAUSS_SEIDEL;
    /* 1e-6 of the brightest emitter: far below what a display or an 8-bit image resolves, and
     * far above the double rounding of the sums (N * 1e-16). */
    o->tol = 1e-6;
    o->atol = 0;
    o->max_iter = 100000;
    o->bounces = 3;
    o->stop = BN_SOLVE_STOP_DEFAULT;
    o->singular_threshold = 1e-6;
    o->divergence = 1e5;
    o->power_iter = 100;
}

void bn_solve_result_free(bn_solve_result *res)
{
    if (!res)
        return;
    free(res->L);
    if (res->terms)
        for (int k = 0; k < res->nterms; k++)
            free(res->terms[k]);
    free(res->terms);
    res->L = NULL;
    res->terms = NULL;
    res->nterms = 0;
}

/* terms[first .. nterms-1] from terms[first-1]: K^q E = K (K^(q-1) E), and D in bounce 1. */
static bn_status bn__terms_extend(const bn_transport *k, const double *D, int first, int nterms, double **terms,
                                  bn_error *err)
{
    size_t m = 3 * bn_transport_size(k);
    for (int q = first; q < nterms; q++) {
        bn_status st = bn_transport_apply(k, terms[q - 1], terms[q], err);
        if (st != BN_OK)
            return st;
        for (size_t i = 0; q == 1 && D && i < m; i++)
            terms[1][i] += D[i];   /* the punctual lights' direct light: bounce 1 */
    }
    return BN_OK;
}

bn_status bn_solve_terms_direct(const bn_transport *k, const double *E, const double *D, int nterms, double **terms,
                                bn_error *err)
{
    if (nterms <= 0)
        return BN_OK;
    memcpy(terms[0], E, 3 * bn_transport_size(k) * sizeof(double));
    return bn__terms_extend(k, D, 1, nterms, terms, err);
}

bn_status bn_solve_terms(const bn_transport *k, const double *E, int nterms, double **terms, bn_error *err)
{
    return bn_solve_terms_direct(k, E, NULL, nterms, terms, err);
}

/* One power step per channel: y = K x, then x = y / ||y_c||_inf. ratio[c]: ||K_c x||_inf / ||x_c||_inf
 * (x_c normalised: ||y_c||_inf); low: max_c min_i y_i / x_i (Collatz-Wielandt). */
static bn_status bn__power_step(const bn_transport *k, double *x, double *y, double ratio[3], double *low,
                                bn_error *err)
{
    size_t n = bn_transport_size(k);
    double xmax[3] = {0, 0, 0}, ymax[3] = {0, 0, 0}, lo[3] = {INFINITY, INFINITY, INFINITY};
    bn_status st = bn_transport_apply(k, x, y, err);   /* y <- K x */
    if (st != BN_OK)
        return st;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            size_t q = 3 * i + (size_t)c;
            xmax[c] = fmax(xmax[c], x[q]);
            ymax[c] = fmax(ymax[c], y[q]);
            if (x[q] > 0)
                lo[c] = fmin(lo[c], y[q] / x[q]);   /* K x >= lo x  =>  rho(K) >= lo */
        }
    *low = 0;
    for (int c = 0; c < 3; c++) {
        ratio[c] = xmax[c] > 0 ? ymax[c] / xmax[c] : 0;
        if (xmax[c] > 0)
            *low = fmax(*low, isfinite(lo[c]) ? lo[c] : 0);
        if (!isfinite(ratio[c]))
            return bn_error_set(err, BN_ENUMERIC, "power iteration: K applied to ones is not finite");
    }
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++)
            x[3 * i + (size_t)c] = ymax[c] > 0 ? y[3 * i + (size_t)c] / ymax[c] : 0;
    return BN_OK;
}

/* The power iteration's start in x: x + 1e-3 of its largest per channel when every channel has a
 * positive value (a previous iterate), else 1. */
static void bn__power_start(double *x, size_t n)
{
    double top[3] = {0, 0, 0};
    for (size_t i = 0; i < 3 * n; i++)
        top[i % 3] = fmax(top[i % 3], x[i]);
    int warm = top[0] > 0 && top[1] > 0 && top[2] > 0 && isfinite(top[0] + top[1] + top[2]);
    for (size_t i = 0; i < 3 * n; i++)
        x[i] = warm && x[i] >= 0 ? x[i] + 1e-3 * top[i % 3] : 1.0;
}

bn_status bn_solve_spectral_radius(const bn_transport *k, size_t max_steps, double *estimate, double *lower,
                                   size_t *steps, bn_error *err)
{
    size_t m = 3 * bn_transport_size(k);
    double *x = bn__calloc(m ? m : 1, sizeof(double));
    if (!x)
        return bn_error_set(err, BN_ENOMEM, "power iteration: out of memory for %zu patches", m / 3);
    bn_status st = bn_solve_spectral_radius_from(k, max_steps, x, estimate, lower, steps, err);
    free(x);
    return st;
}

bn_status bn_solve_spectral_radius_from(const bn_transport *k, size_t max_steps, double *x, double *estimate,
                                        double *lower, size_t *steps, bn_error *err)
{
    size_t n = bn_transport_size(k), m = 3 * n, s;
    double *y = bn__malloc_array(m ? m : 1, sizeof(double));
    double est = 0, low = 0, hist[3] = {-1, -1, -1}, prev_ratio[3] = {0, 0, 0};
    bn_status st = BN_OK;
    *estimate = *lower = 0;
    *steps = 0;
    if (!y)
        return bn_error_set(err, BN_ENOMEM, "power iteration: out of memory for %zu patches", n);
    bn__power_start(x, n);
    if (max_steps == 0)
        max_steps = 1;
    for (s = 1; s <= max_steps; s++) {
        double ratio[3];
        if ((st = bn__power_step(k, x, y, ratio, &low, err)) != BN_OK)
            break;
        /* two steps at once: sqrt(||K^2 x|| / ||x||), as an eigenvalue -lambda near the dominant one (a
         * cavity between two facing surfaces) makes the one-step ratio alternate */
        est = 0;
        for (int c = 0; c < 3; c++)
            est = fmax(est, s > 1 ? sqrt(ratio[c] * prev_ratio[c]) : ratio[c]);
        memcpy(prev_ratio, ratio, sizeof ratio);
        if (est == 0 || (s > 2 && fabs(est - hist[1]) <= 1e-3 * fmax(1.0 - est, 1e-9) &&
                         fabs(est - hist[0]) <= 1e-3 * fmax(1.0 - est, 1e-9)))
            break;   /* settled over the last two steps */
        hist[1] = hist[0];
        hist[0] = est;
    }
    if (st == BN_OK) {
        *estimate = est;
        *lower = low;
        *steps = s > max_steps ? max_steps : s;
    }
    free(y);
    return st;
}

/* ---- the monitor ---- */

static void bn__print_num(FILE *fp, double v)
{
    if (isinf(v))
        fputs(v > 0 ? "inf" : "-inf", fp);
    else
        fprintf(fp, "%.9g", v);
}

static void bn__log_row(FILE *fp, const bn_solve_row *r)
{
    fprintf(fp, "%zu,", r->iteration);
    bn__print_num(fp, r->residual_max);
    fputc(',', fp);
    bn__print_num(fp, r->residual_rms);
    for (int c = 0; c < 3; c++) {
        fputc(',', fp);
        bn__print_num(fp, r->residual_ch[c]);
    }
    fputc(',', fp);
    bn__print_num(fp, r->change);
    fputc(',', fp);
    bn__print_num(fp, r->bound);
    fputc(',', fp);
    bn__print_num(fp, r->error_bound);
    fprintf(fp, ",%.6f\n", r->seconds);
}

/* Norms of r: max over all, RMS over all N*3 entries, max per channel. Serial. */
static void bn__residual_norms(const double *r, size_t n, bn_solve_row *row)
{
    double s2 = 0, nan = 0;
    row->residual_ch[0] = row->residual_ch[1] = row->residual_ch[2] = 0;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            double a = fabs(r[3 * i + (size_t)c]);
            row->residual_ch[c] = fmax(row->residual_ch[c], a);
            s2 += a * a;
            nan += a - a;   /* 0, or NaN for a NaN or infinite entry */
        }
    row->residual_max = fmax(row->residual_ch[0], fmax(row->residual_ch[1], row->residual_ch[2]));
    row->residual_rms = n ? sqrt(s2 / (3.0 * (double)n)) : 0;
    if (nan != 0)   /* fmax drops NaN: a NaN or infinite residual is never reported as small */
        row->residual_max = row->residual_rms = NAN;
}

/* First non-finite entry of x (N*3), or SIZE_MAX. */
static size_t bn__first_nonfinite(const double *x, size_t m)
{
    for (size_t i = 0; i < m; i++)
        if (!isfinite(x[i]))
            return i;
    return SIZE_MAX;
}

static const bn_solver_type *bn__solver_for(const bn_solve_opts *o)
{
    switch (o->method) {
    case BN_SOLVE_JACOBI: return &bn__solver_jacobi;
    case BN_SOLVE_GAUSS_SEIDEL: return o->symmetric ? &bn__solver_gauss_seidel_symmetric : &bn__solver_gauss_seidel;
    case BN_SOLVE_NEUMANN: return &bn__solver_neumann;
    case BN_SOLVE_DIRECT: return &bn__solver_direct;
    }
    return NULL;
}

int bn_solve_method_runs_on(bn_solve_method m, const bn_transport *k)
{
    bn_solve_opts o = {.method = m};
    const bn_solver_type *t = bn__solver_for(&o);
    return t && (t->needs & ~bn_transport_caps(k)) == 0;
}

static void bn__note(const bn_solve_opts *o, bn_log_level lv, const char *fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
static void bn__note(const bn_solve_opts *o, bn_log_level lv, const char *fmt, ...)
{
    char buf[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    if (lv != BN_LOG_WARN && o->quiet)
        return;
    bn_logf(&o->log_sink, lv, "%s", buf);
}

/* Iterations for rate^k * r0 <= target (the Jacobi / Neumann rate; Gauss-Seidel is at most this
 * by Stein-Rosenberg for nonnegative K). */
static size_t bn__predict(double rate, double r0, double target)
{
    double k;
    if (r0 <= target)
        return 0;
    if (!(rate > 0))
        return 1;
    if (rate >= 1 || target <= 0)
        return SIZE_MAX;
    k = ceil(log(target / r0) / log(rate));
    return k > 1e18 ? SIZE_MAX : (size_t)fmax(k, 1);
}

static void bn__write_log_head(const bn_solve_opts *o, const bn_transport *k, const bn_solve_result *res,
                               double thr, bn_solve_stop stop)
{
    FILE *fp = o->log;
    if (!fp)
        return;
    if (o->log_header && *o->log_header) {
        fputs(o->log_header, fp);
        if (o->log_header[strlen(o->log_header) - 1] != '\n')
            fputc('\n', fp);
    }
    fprintf(fp, "# version=%s\n# method=%s%s\n# tol=%.9g\n# atol=%.9g\n# max_iter=%zu\n# stop=%s\n# bounces=%d\n",
            bn_version(), bn_solve_method_name(o->method), o->symmetric && o->method == BN_SOLVE_GAUSS_SEIDEL ? "-symmetric" : "",
            o->tol, o->atol, o->max_iter, bn_solve_stop_name(stop), o->bounces);
    fprintf(fp, "# patches=%zu\n# transport=%s\n# norm_E=%.9g\n# k_norm_inf=%.9g\n# spectral_radius=%.9g\n"
                "# spectral_radius_lower=%.9g\n# power_iterations=%zu\n# singular_threshold=%.3g\n",
            res->n, bn_transport_name(k), res->norm_E, res->k_norm_inf, res->spectral_radius,
            res->spectral_radius_lower, res->power_iterations, thr);
    if (res->predicted_iterations == SIZE_MAX)
        fprintf(fp, "# predicted_iterations=inf\n");
    else
        fprintf(fp, "# predicted_iterations=%zu\n", res->predicted_iterations);
    fprintf(fp, "%s\n", BN_SOLVE_LOG_COLUMNS);
}

static int bn__emit_row(const bn_solve_opts *o, const bn_solve_row *row, const double *L)
{
    if (o->log)
        bn__log_row(o->log, row);
    return o->monitor ? o->monitor(o->monitor_user, row, L) : 0;
}

/* ---- the driver: check, analyse, iterate (or solve directly), keep the terms ---- */

/* Everything one solve holds; each stage below reads and fills its part. */
typedef struct bn__solve {
    const bn_transport *k;
    const double *E;                /* the source: the emission, plus the punctual lights' direct light */
    const double *Esurf;            /* the emission alone (bounce 0) */
    double *src;                    /* owned when E is Esurf + o->direct */
    const bn_solve_opts *o;
    const bn_solver_type *type;
    bn_solve_result *res;
    bn_error *err;
    bn_solve_stop stop;
    size_t n, m;
    double t0, knorm, target, r0max;
    double kpow;                    /* ||K||^(s k + 1) at iteration k (s sweeps per iteration) */
    double *diag, *r, *Lprev, *y;   /* diag NULL when K_ii = 0 for every i (or unknown) */
    int filled;                     /* terms K^0 E .. K^(filled-1) E made so far */
    int lazy;                       /* the spectral radius from the residuals (bn_solve_opts.power_lazy) */
    double rch[4][3];               /* lazy: the largest residual per channel, the last four rows */
    int r0_signed;                  /* lazy: r0 has a negative entry (a start near the answer) */
    bn_solve_row row;
} bn__solve;

/* A non-finite value at x[bad]: the patch, and the reason the solve stopped. */
static void bn__solve_nonfinite(bn__solve *S, size_t bad)
{
    S->res->bad_patch = bad / 3;
    S->res->reason = BN_STOP_DIVERGED_NAN;
}

bn_status bn_solve_opts_check(const bn_solve_opts *o, bn_error *err)
{
    if (!(o->tol >= 0 && isfinite(o->tol)))
        return bn_error_set(err, BN_EUSAGE, "tol %g is not a finite tolerance >= 0", o->tol);
    if (!(o->atol >= 0 && isfinite(o->atol)))
        return bn_error_set(err, BN_EUSAGE, "atol %g is not a finite tolerance >= 0", o->atol);
    if (o->max_iter < 1)
        return bn_error_set(err, BN_EUSAGE, "max_iter %zu: at least 1 iteration is needed", o->max_iter);
    if (o->bounces > BN_SOLVE_MAX_BOUNCES)
        return bn_error_set(err, BN_EUSAGE, "bounces %d is above %d: each term is a whole vector, image layer and "
                            "bake attribute; the tail of the series is kept as rest", o->bounces, BN_SOLVE_MAX_BOUNCES);
    if (o->threads < 0)
        return bn_error_set(err, BN_EUSAGE, "threads %d is negative (0: all cores)", o->threads);
    if (!(o->singular_threshold >= 0 && o->singular_threshold < 1))
        return bn_error_set(err, BN_EUSAGE, "singular_threshold %g is outside [0, 1)", o->singular_threshold);
    if (!(o->divergence >= 0) || isnan(o->divergence))
        return bn_error_set(err, BN_EUSAGE, "divergence %g is not >= 0 (0: no growth test)", o->divergence);
    if ((unsigned)o->method > BN_SOLVE_DIRECT)
        return bn_error_set(err, BN_EUSAGE, "unknown solve method %d", (int)o->method);
    if ((unsigned)o->stop > BN_SOLVE_STOP_PATCH)
        return bn_error_set(err, BN_EUSAGE, "unknown stop test %d", (int)o->stop);
    return BN_OK;
}

/* Options, the method, what it needs of K, and E (finite, nonnegative). */
static bn_status bn__solve_check(bn__solve *S)
{
    const bn_solve_opts *o = S->o;
    bn_solve_result *res = S->res;
    size_t bad;
    bn_status st = bn_solve_opts_check(o, S->err);
    if (st != BN_OK)
        return st;
    if (bn_transport_require(S->k, S->type->needs, S->type->name, S->err) != BN_OK)
        return S->err ? S->err->status : BN_ENOTSUP;
    S->stop = o->stop;
    if (S->stop == BN_SOLVE_STOP_DEFAULT)
        S->stop = o->method == BN_SOLVE_NEUMANN ? BN_SOLVE_STOP_BOUND : BN_SOLVE_STOP_RESIDUAL;
    bad = bn__first_nonfinite(S->E, S->m);
    if (bad != SIZE_MAX) {
        res->bad_patch = bad / 3;
        return bn_error_set(S->err, BN_EINPUT, "emission E of patch %zu (channel %c) is %g", bad / 3, "RGB"[bad % 3],
                            S->E[bad]);
    }
    for (size_t i = 0; i < S->m; i++) {
        if (S->E[i] < 0) {
            res->bad_patch = i / 3;
            return bn_error_set(S->err, BN_EINPUT, "emission E of patch %zu (channel %c) is negative (%g)", i / 3,
                                "RGB"[i % 3], S->E[i]);
        }
        res->norm_E = fmax(res->norm_E, S->E[i]);
    }
    S->r = bn__malloc_array(S->m ? S->m : 1, sizeof(double));
    S->y = bn__malloc_array(S->m ? S->m : 1, sizeof(double));
    S->Lprev = bn__malloc_array(S->m ? S->m : 1, sizeof(double));
    res->L = bn__malloc_array(S->m ? S->m : 1, sizeof(double));
    if (!S->r || !S->y || !S->Lprev || !res->L)
        return bn_error_set(S->err, BN_ENOMEM, "solve: out of memory for vectors of %zu patches", S->n);
    return BN_OK;
}

/* ||K||_inf (K applied to ones, F >= 0): finite and nonnegative rows, or a failure naming one. */
static bn_status bn__solve_norm(bn__solve *S)
{
    bn_status st = bn_transport_norm_inf(S->k, &S->knorm, NULL, &S->res->bad_patch, S->err);
    if (st == BN_OK)
        S->res->k_norm_inf = S->knorm;
    return st;
}

/* K_ii = rho_ic F_ii where the operator knows F_ii; NULL diag when all are 0 or it cannot say. */
static bn_status bn__solve_diag(bn__solve *S)
{
    const double *rho = bn_transport_rho(S->k);
    int any = 0;
    bn_status st;
    if (!(bn_transport_caps(S->k) & (BN_OP_DIAG | BN_OP_ENTRIES)))
        return BN_OK;
    S->diag = bn__malloc_array(S->m ? S->m : 1, sizeof(double));
    if (!S->diag)
        return bn_error_set(S->err, BN_ENOMEM, "solve: out of memory for the diagonal");
    st = bn_transport_diag(S->k, S->y, S->err);   /* F_ii into scratch */
    if (st != BN_OK)
        return st;
    for (size_t i = 0; i < S->n; i++)
        for (int c = 0; c < 3; c++) {
            S->diag[3 * i + (size_t)c] = rho[3 * i + (size_t)c] * S->y[i];
            any |= S->y[i] != 0;
        }
    if (!any) {
        free(S->diag);
        S->diag = NULL;
    }
    return BN_OK;
}

/* Refuses a (near-)singular I - K before any iteration. */
static bn_status bn__solve_singular(bn__solve *S)
{
    bn_solve_result *res = S->res;
    double thr = S->o->singular_threshold, gap = 1.0 - thr;
    if (res->spectral_radius_lower >= gap || (S->knorm >= gap && res->spectral_radius >= gap)) {
        res->reason = BN_STOP_SINGULAR;
        return bn_error_set(S->err, BN_ENUMERIC,
                            "I - K is singular within F's accuracy: ||K||_inf = %.9g and the spectral radius of K is "
                            "%.9g (at least %.9g), not below 1 - %g (the threshold: F's row sums are only known to "
                            "about that; the error bound delta/(1 - ||K||) would exceed 100%%). A closed scene with "
                            "reflectance 1 reflects light forever. Lower the reflectance, open the scene, or set the "
                            "threshold to F's row-sum error if you know it is smaller",
                            S->knorm, res->spectral_radius, res->spectral_radius_lower, thr);
    }
    if (S->knorm >= 1 && S->o->log)   /* the convergence table's bound columns: say they are void */
        bn_warnf(&S->o->log_sink, BN_W_BOUNDS, S->knorm,
                 "||K||_inf = %.9g >= 1 but the spectral radius is %.9g < 1: the iterations converge, but the a "
                 "priori bounds (bound, error_bound columns) do not apply",
                 S->knorm, res->spectral_radius);
    else if (S->knorm >= 1)   /* no table with bounds: nothing is wrong with what this run writes */
        bn_logf(&S->o->log_sink, BN_LOG_INFO, "||K||_inf = %.9g >= 1 but the spectral radius is %.9g < 1: the "
                "iterations converge (the a priori error bounds, which need ||K|| < 1, are not used)", S->knorm,
                res->spectral_radius);
    return BN_OK;
}

/* L0 = E, r0 = K E, the target and the predicted iteration count (said in a note). */
static bn_status bn__solve_start(bn__solve *S)
{
    const bn_solve_opts *o = S->o;
    bn_solve_result *res = S->res;
    double tgt;
    bn_status st;
    memcpy(res->L, S->E, S->m * sizeof(double));
    st = bn_transport_apply(S->k, S->E, S->r, S->err);   /* r0 = E - (I - K) E = K E */
    if (st != BN_OK)
        return st;
    memset(&S->row, 0, sizeof S->row);
    bn__residual_norms(S->r, S->n, &S->row);
    S->r0max = S->row.residual_max;
    for (size_t i = 0; S->lazy && i < S->m; i++)
        S->r0_signed |= S->r[i] < 0;
    S->target = o->tol * res->norm_E;
    tgt = fmax(S->target, o->atol);
    if (S->stop == BN_SOLVE_STOP_BOUND && S->knorm < 1)
        tgt *= 1.0 - S->knorm;   /* ||r|| / (1 - ||K||) <= target */
    res->predicted_iterations = S->lazy ? SIZE_MAX : bn__predict(res->spectral_radius, S->r0max, tgt);
    if (S->type->sweeps == 2 && res->predicted_iterations != SIZE_MAX)
        res->predicted_iterations = (res->predicted_iterations + 1) / 2;
    if (S->lazy)
        bn__note(o, BN_LOG_INFO, "||K||_inf = %.9g < 1: no power iteration first; the spectral radius from the "
                 "iterations' residuals", S->knorm);
    else if (res->predicted_iterations == SIZE_MAX)
        bn__note(o, BN_LOG_INFO, "spectral radius ~ %.9g (>= %.9g, %zu power steps); ||K||_inf = %.9g; the tolerance "
                 "cannot be predicted", res->spectral_radius, res->spectral_radius_lower, res->power_iterations, S->knorm);
    else
        bn__note(o, BN_LOG_INFO,
                 "spectral radius ~ %.9g (>= %.9g, %zu power steps); ||K||_inf = %.9g; predicted %zu %s to "
                 "tol %g (rate rho^k%s)",
                 res->spectral_radius, res->spectral_radius_lower, res->power_iterations, S->knorm,
                 res->predicted_iterations, o->method == BN_SOLVE_NEUMANN ? "bounces" : "iterations", o->tol,
                 o->method == BN_SOLVE_GAUSS_SEIDEL ? "; Gauss-Seidel needs at most this, often about half" : "");
    if (res->predicted_iterations != SIZE_MAX && res->predicted_iterations > o->max_iter && S->type->solve == NULL)
        bn_warnf(&o->log_sink, BN_W_ITERATIONS, (double)res->predicted_iterations, "the predicted %zu iterations exceed `max_iter` %zu: expect the iteration limit",
                 res->predicted_iterations, o->max_iter);
    return BN_OK;
}

/* Norms, diagonal, spectral radius, the singularity check, the start and the log's head. */
static bn_status bn__solve_analyse(bn__solve *S)
{
    bn_status st = bn__solve_norm(S);
    if (st == BN_OK)
        st = bn__solve_diag(S);
    S->lazy = st == BN_OK && S->o->power_lazy && !S->o->log && !S->type->solve && S->type->sweeps == 1 &&
              S->o->method != BN_SOLVE_GAUSS_SEIDEL && S->knorm < 1.0 - S->o->singular_threshold;
    if (st == BN_OK && !S->lazy)
        st = S->o->power_start
                 ? bn_solve_spectral_radius_from(S->k, S->o->power_iter, S->o->power_start, &S->res->spectral_radius,
                                                 &S->res->spectral_radius_lower, &S->res->power_iterations, S->err)
                 : bn_solve_spectral_radius(S->k, S->o->power_iter, &S->res->spectral_radius,
                                            &S->res->spectral_radius_lower, &S->res->power_iterations, S->err);
    if (st == BN_OK)
        st = bn__solve_singular(S);
    if (st == BN_OK)
        st = bn__solve_start(S);
    S->res->seconds_analyse = bn__now() - S->t0;
    if (st == BN_OK)
        bn__write_log_head(S->o, S->k, S->res, S->o->singular_threshold, S->stop);
    return st;
}

/* r <- E - (I - K) L. */
static bn_status bn__solve_residual(bn__solve *S, const double *L)
{
    bn_status st = bn_transport_apply(S->k, L, S->y, S->err);
    if (st != BN_OK)
        return st;
    for (size_t i = 0; i < S->m; i++)
        S->r[i] = S->E[i] - L[i] + S->y[i];
    return BN_OK;
}

/* One iteration of the method, its residual and the change it made. */
static bn_status bn__solve_step(bn__solve *S, void *state)
{
    double *L = S->res->L;
    int have_r = 0;
    bn_status st;
    memcpy(S->Lprev, L, S->m * sizeof(double));
    st = S->type->iterate(state, L, S->r, &have_r, S->err);
    if (st == BN_OK && !have_r)
        st = bn__solve_residual(S, L);
    if (st != BN_OK)
        return st;
    bn__residual_norms(S->r, S->n, &S->row);
    S->row.change = 0;
    for (size_t i = 0; i < S->m; i++)
        S->row.change = fmax(S->row.change, fabs(L[i] - S->Lprev[i]));
    return BN_OK;
}

/* The row's bounds: a priori ||K||^(s k + 1) / (1 - ||K||) ||E||, a posteriori ||r|| / (1 - ||K||). */
static void bn__solve_bounds(bn__solve *S, size_t it)
{
    if (it == 0)
        S->kpow = S->knorm;
    else
        for (int q = 0; q < S->type->sweeps; q++)
            S->kpow *= S->knorm;
    S->row.iteration = it;
    S->row.bound = S->knorm < 1 ? S->kpow / (1 - S->knorm) * S->res->norm_E : INFINITY;
    S->row.error_bound = S->knorm < 1 ? S->row.residual_max / (1 - S->knorm) : INFINITY;
    S->row.seconds = bn__now() - S->t0;
}

/* The patch stop test's measure: the largest residual relative to its own patch's radiance, over
 * the entries whose residual is above atol. */
static double bn__patch_measure(const bn__solve *S)
{
    double m = 0;
    for (size_t i = 0; i < S->m; i++) {
        double r = fabs(S->r[i]), l = fabs(S->res->L[i]);
        if (r > S->o->atol)
            m = fmax(m, l > 0 ? r / l : INFINITY);
    }
    return m;
}

/* After a row: *done = 1 with the stop reason set (and the status of a failed stop), or 0 to go on. */
static bn_status bn__solve_stop_test(bn__solve *S, int *done)
{
    const bn_solve_opts *o = S->o;
    bn_solve_result *res = S->res;
    const bn_solve_row *row = &S->row;
    size_t it = row->iteration;
    double measure = S->stop == BN_SOLVE_STOP_BOUND && S->knorm < 1 ? row->error_bound : row->residual_max;
    *done = 1;
    if (S->stop == BN_SOLVE_STOP_PATCH ? bn__patch_measure(S) <= o->tol : measure <= S->target) {
        res->reason = BN_STOP_CONVERGED_RTOL;
        return BN_OK;
    }
    if (measure <= o->atol) {
        res->reason = BN_STOP_CONVERGED_ATOL;
        return BN_OK;
    }
    if (o->divergence > 0 && row->residual_max > o->divergence * fmax(S->r0max, DBL_MIN)) {
        res->reason = BN_STOP_DIVERGED_GROWTH;
        return bn_error_set(S->err, BN_ENUMERIC, "%s diverged: residual %.6g at iteration %zu is %.3g times the initial %.6g",
                            S->type->name, row->residual_max, it, row->residual_max / S->r0max, S->r0max);
    }
    if (it >= o->max_iter) {
        res->reason = BN_STOP_MAX_ITER;
        return bn_error_set(S->err, BN_ENOTCONV,
                            "%s did not converge within %zu iterations: residual %.6g > %.6g (tol %g x ||E|| %.6g)%s",
                            S->type->name, o->max_iter, row->residual_max, fmax(S->target, o->atol), o->tol,
                            res->norm_E,
                            res->predicted_iterations != SIZE_MAX ? "; raise `max_iter` to the predicted count" : "");
    }
    if (bn_interrupted() != BN_OK)
        return bn_error_set(S->err, bn_interrupted(), "%s interrupted at iteration %zu", S->type->name, it);
    *done = 0;
    return BN_OK;
}

/* The terms' arrays, before the iteration (which may fill some: bn__solve_capture), terms[0] = E. */
static bn_status bn__solve_alloc_terms(bn__solve *S)
{
    bn_solve_result *res = S->res;
    if (S->o->bounces < 0)
        return BN_OK;
    res->nterms = S->o->bounces + 1;
    res->terms = bn__calloc((size_t)res->nterms, sizeof(double *));
    if (!res->terms) {
        res->nterms = 0;
        return bn_error_set(S->err, BN_ENOMEM, "solve: out of memory for %d bounce terms", S->o->bounces + 1);
    }
    for (int q = 0; q < res->nterms; q++)
        if (!(res->terms[q] = bn__malloc_array(S->m ? S->m : 1, sizeof(double))))
            return bn_error_set(S->err, BN_ENOMEM, "solve: out of memory for %d bounce terms of %zu patches",
                                S->o->bounces + 1, S->n);
    memcpy(res->terms[0], S->Esurf, S->m * sizeof(double));
    S->filled = 1;
    return BN_OK;
}

/* A method whose residual after iteration `it` is the next term, K^(it+1) E, computed as the terms are
 * (bn_solver_type.residual_is_term: the Neumann series) leaves the terms as it goes: they are not
 * computed again after the iteration. Not with punctual lights (the iteration then runs on E + direct,
 * the terms on E). */
static void bn__solve_capture(bn__solve *S, size_t it)
{
    bn_solve_result *res = S->res;
    if (!S->type->residual_is_term || S->o->direct || !res->terms || (size_t)S->filled != it + 1 ||
        S->filled >= res->nterms)
        return;
    memcpy(res->terms[S->filled++], S->r, S->m * sizeof(double));
}

/* sweep -> residual -> bounds -> NaN check -> monitor row -> stop test, from row 0 (L0 = E). */
static bn_status bn__solve_iterate(bn__solve *S)
{
    bn__solve_ctx ctx = {S->k, S->E, S->diag, S->o, S->n};
    void *state = bn__calloc(1, S->type->state_size);
    bn_status st;
    int done = 0;
    if (!state)
        return bn_error_set(S->err, BN_ENOMEM, "solve: out of memory");
    st = S->type->setup(state, &ctx, S->res->L, S->r, S->err);
    for (size_t it = 0; st == BN_OK && !done; it++) {
        size_t bad;
        if (it > 0 && (st = bn__solve_step(S, state)) != BN_OK)
            break;
        bn__solve_bounds(S, it);
        bn__solve_capture(S, it);
        if (S->lazy) {
            memmove(S->rch[1], S->rch[0], 3 * sizeof S->rch[0]);
            memcpy(S->rch[0], S->row.residual_ch, sizeof S->rch[0]);
        }
        S->res->iterations = it;
        bad = bn__first_nonfinite(S->res->L, S->m);
        if (bad != SIZE_MAX || !isfinite(S->row.residual_max)) {
            if (bad == SIZE_MAX)
                bad = bn__first_nonfinite(S->r, S->m);
            bn__solve_nonfinite(S, bad);
            st = bn_error_set(S->err, BN_ENUMERIC, "%s: iteration %zu produced a non-finite value at patch %zu (channel %c)",
                              S->type->name, it, bad / 3, "RGB"[bad % 3]);
            break;
        }
        if (bn__emit_row(S->o, &S->row, S->res->L)) {
            st = bn_error_set(S->err, BN_EINTR, "%s: stopped by the monitor at iteration %zu", S->type->name, it);
            break;
        }
        st = bn__solve_stop_test(S, &done);
    }
    S->type->cleanup(state);
    free(state);
    return st;
}

/* The direct method: L at once, then its residual as the one row of the table. */
static bn_status bn__solve_direct(bn__solve *S)
{
    bn__solve_ctx ctx = {S->k, S->E, S->diag, S->o, S->n};
    int singular = 0;
    size_t bad;
    bn_status st = S->type->solve(&ctx, S->res->L, &singular, S->err);
    if (st != BN_OK) {
        if (singular)
            S->res->reason = BN_STOP_SINGULAR;
        return st;
    }
    bad = bn__first_nonfinite(S->res->L, S->m);
    if (bad != SIZE_MAX) {
        bn__solve_nonfinite(S, bad);
        return bn_error_set(S->err, BN_ENUMERIC, "direct solve: L of patch %zu (channel %c) is %g", bad / 3,
                            "RGB"[bad % 3], S->res->L[bad]);
    }
    st = bn__solve_residual(S, S->res->L);
    if (st != BN_OK)
        return st;
    bn__residual_norms(S->r, S->n, &S->row);
    S->row.iteration = 0;
    S->row.change = 0;
    S->row.bound = 0;
    S->row.error_bound = S->knorm < 1 ? S->row.residual_max / (1 - S->knorm) : INFINITY;
    S->row.seconds = bn__now() - S->t0;
    S->res->reason = BN_STOP_DIRECT;
    S->res->iterations = 0;
    bn__emit_row(S->o, &S->row, S->res->L);
    return BN_OK;
}

/* The per-bounce terms the iteration did not leave, from the last one it kept. */
static bn_status bn__solve_keep_terms(bn__solve *S)
{
    return bn__terms_extend(S->k, S->o->direct, S->filled, S->res->nterms, S->res->terms, S->err);
}

/* The source E + direct when punctual lights give some (the emission alone otherwise). */
static bn_status bn__solve_source(bn__solve *S)
{
    if (!S->o->direct)
        return BN_OK;
    if (!(S->src = bn__malloc_array(S->m ? S->m : 1, sizeof(double))))
        return bn_error_set(S->err, BN_ENOMEM, "solve: out of memory for the source of %zu patches", S->n);
    for (size_t i = 0; i < S->m; i++)
        S->src[i] = S->Esurf[i] + S->o->direct[i];
    S->E = S->src;
    return BN_OK;
}

/* lazy: the spectral radius from the last residuals, r_k = K^k r_0 with r_0 >= 0 (K >= 0: the largest
 * entry's ratio tends to rho(K)), over two steps (an eigenvalue near -rho makes one step's ratio
 * alternate), taken when the last two such estimates agree within 1%; the last residual is then the next
 * power iteration's start. Otherwise (a signed r_0, too few iterations, not settled) the power iteration
 * after all, from power_start. */
static double bn__lazy_est(const double a[3], const double b[3])
{
    double est = 0;
    for (int c = 0; c < 3; c++)
        if (b[c] > 0)
            est = fmax(est, sqrt(a[c] / b[c]));
    return est;
}

static bn_status bn__solve_lazy_radius(bn__solve *S)
{
    bn_solve_result *res = S->res;
    if (!S->lazy)
        return BN_OK;
    double now = bn__lazy_est(S->rch[0], S->rch[2]), before = bn__lazy_est(S->rch[1], S->rch[3]);
    if (!S->r0_signed && res->iterations >= 3 && now > 0 && fabs(now - before) <= 0.01 * now) {
        res->spectral_radius = now;
        if (S->o->power_start)
            for (size_t i = 0; i < S->m; i++)
                S->o->power_start[i] = fabs(S->r[i]);
        return BN_OK;
    }
    return S->o->power_start
               ? bn_solve_spectral_radius_from(S->k, S->o->power_iter, S->o->power_start, &res->spectral_radius,
                                               &res->spectral_radius_lower, &res->power_iterations, S->err)
               : bn_solve_spectral_radius(S->k, S->o->power_iter, &res->spectral_radius, &res->spectral_radius_lower,
                                          &res->power_iterations, S->err);
}

static void bn__solve_record(bn__solve *S)
{
    bn_solve_result *res = S->res;
    res->residual_max = S->row.residual_max;
    res->residual_rms = S->row.residual_rms;
    memcpy(res->residual_ch, S->row.residual_ch, sizeof S->row.residual_ch);
    res->change = S->row.change;
    res->error_bound = S->row.error_bound;
}

static bn_status bn__solve_body(const bn_transport *k, const double *E, const bn_solve_opts *o, bn_solve_result *res,
                   bn_error *err)
{
    bn__solve S;
    bn_status st, run = BN_OK, lz;
    double t;
    memset(&S, 0, sizeof S);
    memset(res, 0, sizeof *res);
    S.k = k;
    S.E = S.Esurf = E;
    S.o = o;
    S.res = res;
    S.err = err;
    S.type = bn__solver_for(o);
    S.n = bn_transport_size(k);
    S.m = 3 * S.n;
    S.t0 = bn__now();
    res->n = S.n;
    res->method = o->method;
    res->bad_patch = SIZE_MAX;
    res->reason = BN_STOP_NONE;

    st = bn__solve_source(&S);
    if (st == BN_OK)
        st = bn__solve_check(&S);
    if (st == BN_OK)
        st = bn__solve_alloc_terms(&S);
    if (st == BN_OK)
        st = bn__solve_analyse(&S);
    if (st == BN_OK) {
        t = bn__now();
        run = S.type->solve ? bn__solve_direct(&S) : bn__solve_iterate(&S);
        res->seconds_iterate = bn__now() - t;
        bn__solve_record(&S);
        if (run == BN_OK || run == BN_ENOTCONV)   /* a lazy spectral radius (its failure is the run's) */
            run = (lz = bn__solve_lazy_radius(&S)) != BN_OK ? lz : run;
        /* The iteration limit is a failure that keeps its answer (the caller may want it). */
        st = run == BN_ENOTCONV ? BN_OK : run;
    }
    if (st == BN_OK) {
        t = bn__now();
        st = bn__solve_keep_terms(&S);
        res->seconds_terms = bn__now() - t;
        if (st == BN_OK)
            st = run;
    }
    res->seconds = bn__now() - S.t0;
    if (st == BN_ENUMERIC && res->bad_patch == SIZE_MAX && bn_transport_nonfinite_patch(k) != SIZE_MAX) {
        res->bad_patch = bn_transport_nonfinite_patch(k);
        res->reason = BN_STOP_DIVERGED_NAN;
    }
    free(S.src);
    free(S.diag);
    free(S.r);
    free(S.y);
    free(S.Lprev);
    if (st != BN_OK && st != BN_ENOTCONV)
        bn_solve_result_free(res);   /* no NaN and no half answer leaves a failed solve */
    return st;
}

bn_status bn_solve(const bn_transport *k, const double *E, const bn_solve_opts *o, bn_solve_result *res,
                   bn_error *err)
{
    int prev = bn__threads_begin(o->threads);
    bn_status st = bn__solve_body(k, E, o, res, err);
    bn__threads_end(prev);
    return st;
}
