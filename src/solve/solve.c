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

const char *bn_solve_method_name(bn_solve_method m)
{
    switch (m) {
    case BN_SOLVE_JACOBI: return "jacobi";
    case BN_SOLVE_GAUSS_SEIDEL: return "gauss-seidel";
    case BN_SOLVE_NEUMANN: return "neumann";
    case BN_SOLVE_DIRECT: return "direct";
    }
    return "?";
}

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

const char *bn_solve_stop_name(bn_solve_stop s)
{
    switch (s) {
    case BN_SOLVE_STOP_DEFAULT: return "default";
    case BN_SOLVE_STOP_RESIDUAL: return "residual";
    case BN_SOLVE_STOP_BOUND: return "bound";
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

void bn_solve_terms(const bn_transport *k, const double *E, int nterms, double **terms)
{
    size_t m = 3 * bn_transport_size(k);
    if (nterms <= 0)
        return;
    memcpy(terms[0], E, m * sizeof(double));
    for (int q = 1; q < nterms; q++)
        bn_transport_apply(k, terms[q - 1], terms[q]);   /* K^q E <- K (K^(q-1) E) */
}

bn_status bn_solve_spectral_radius(const bn_transport *k, size_t max_steps, double *estimate, double *lower,
                                   size_t *steps, bn_error *err)
{
    size_t n = bn_transport_size(k), m = 3 * n, s;
    double *x = bn__malloc_array(m ? m : 1, sizeof(double)), *y = bn__malloc_array(m ? m : 1, sizeof(double));
    double prev = -1, est = 0, low = 0;
    *estimate = *lower = 0;
    *steps = 0;
    if (!x || !y) {
        free(x);
        free(y);
        return bn_error_set(err, BN_ENOMEM, "power iteration: out of memory for %zu patches", n);
    }
    for (size_t i = 0; i < m; i++)
        x[i] = 1.0;
    if (max_steps == 0)
        max_steps = 1;
    for (s = 1; s <= max_steps; s++) {
        double xmax[3] = {0, 0, 0}, ymax[3] = {0, 0, 0}, lo[3] = {INFINITY, INFINITY, INFINITY};
        bn_transport_apply(k, x, y);   /* y <- K x */
        for (size_t i = 0; i < n; i++)
            for (int c = 0; c < 3; c++) {
                size_t q = 3 * i + (size_t)c;
                xmax[c] = fmax(xmax[c], x[q]);
                ymax[c] = fmax(ymax[c], y[q]);
                if (x[q] > 0)
                    lo[c] = fmin(lo[c], y[q] / x[q]);   /* K x >= lo x  =>  rho(K) >= lo */
            }
        est = low = 0;
        for (int c = 0; c < 3; c++) {
            if (xmax[c] > 0) {
                est = fmax(est, ymax[c] / xmax[c]);
                low = fmax(low, isfinite(lo[c]) ? lo[c] : 0);
            }
        }
        if (!isfinite(est)) {
            free(x);
            free(y);
            return bn_error_set(err, BN_ENUMERIC, "power iteration: K applied to ones is not finite");
        }
        /* x <- y / ||y_c||_inf per channel */
        for (size_t i = 0; i < n; i++)
            for (int c = 0; c < 3; c++)
                x[3 * i + (size_t)c] = ymax[c] > 0 ? y[3 * i + (size_t)c] / ymax[c] : 0;
        if (est == 0 || fabs(est - prev) <= 1e-3 * fmax(1.0 - est, 1e-9))
            break;
        prev = est;
    }
    *estimate = est;
    *lower = low;
    *steps = s > max_steps ? max_steps : s;
    free(x);
    free(y);
    return BN_OK;
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
    double s2 = 0;
    row->residual_ch[0] = row->residual_ch[1] = row->residual_ch[2] = 0;
    for (size_t i = 0; i < n; i++)
        for (int c = 0; c < 3; c++) {
            double a = fabs(r[3 * i + (size_t)c]);
            row->residual_ch[c] = fmax(row->residual_ch[c], a);
            s2 += a * a;
        }
    row->residual_max = fmax(row->residual_ch[0], fmax(row->residual_ch[1], row->residual_ch[2]));
    row->residual_rms = n ? sqrt(s2 / (3.0 * (double)n)) : 0;
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

bn_status bn_solve(const bn_transport *k, const double *E, const bn_solve_opts *o, bn_solve_result *res,
                   bn_error *err)
{
    size_t n = bn_transport_size(k), m = 3 * n, bad;
    const bn_solver_type *type = bn__solver_for(o);
    bn_solve_stop stop = o->stop;
    double t0 = bn__now(), t1, knorm, thr = o->singular_threshold, target, r0max, gap;
    double *ones = NULL, *rs = NULL, *diag = NULL, *r = NULL, *Lprev = NULL;
    void *state = NULL;
    int have_diag = 0, state_ready = 0;
    bn__solve_ctx ctx;
    bn_solve_row row;
    bn_status st = BN_OK;

    memset(res, 0, sizeof *res);
    res->n = n;
    res->method = o->method;
    res->bad_patch = SIZE_MAX;
    res->reason = BN_STOP_NONE;
    if (!type)
        return bn_error_set(err, BN_EUSAGE, "unknown solve method %d", (int)o->method);
    if (!(o->tol >= 0) || !(o->atol >= 0) || !isfinite(o->tol) || !isfinite(o->atol))
        return bn_error_set(err, BN_EUSAGE, "tolerances must be finite and >= 0 (tol %g, atol %g)", o->tol, o->atol);
    if (!(thr >= 0 && thr < 1))
        return bn_error_set(err, BN_EUSAGE, "singular threshold %g is outside [0, 1)", thr);
    if (stop == BN_SOLVE_STOP_DEFAULT)
        stop = o->method == BN_SOLVE_NEUMANN ? BN_SOLVE_STOP_BOUND : BN_SOLVE_STOP_RESIDUAL;

    /* ---- analysis: E, K, norms, spectral radius, singularity, prediction ---- */
    bad = bn__first_nonfinite(E, m);
    if (bad != SIZE_MAX) {
        res->bad_patch = bad / 3;
        return bn_error_set(err, BN_EINPUT, "emission E of patch %zu (channel %c) is %g", bad / 3, "RGB"[bad % 3], E[bad]);
    }
    for (size_t i = 0; i < m; i++) {
        if (E[i] < 0) {
            res->bad_patch = i / 3;
            return bn_error_set(err, BN_EINPUT, "emission E of patch %zu (channel %c) is negative (%g)", i / 3,
                                "RGB"[i % 3], E[i]);
        }
        res->norm_E = fmax(res->norm_E, E[i]);
    }
    ones = bn__malloc_array(m ? m : 1, sizeof(double));
    rs = bn__malloc_array(m ? m : 1, sizeof(double));
    diag = bn__malloc_array(m ? m : 1, sizeof(double));
    r = bn__malloc_array(m ? m : 1, sizeof(double));
    Lprev = bn__malloc_array(m ? m : 1, sizeof(double));
    res->L = bn__malloc_array(m ? m : 1, sizeof(double));
    if (!ones || !rs || !diag || !r || !Lprev || !res->L) {
        st = bn_error_set(err, BN_ENOMEM, "solve: out of memory for vectors of %zu patches", n);
        goto fail;
    }
    /* ||K||_inf = max_ic rho_ic sum_j F_ij: K applied to ones (F >= 0) */
    for (size_t i = 0; i < m; i++)
        ones[i] = 1.0;
    bn_transport_apply(k, ones, rs);
    knorm = 0;
    for (size_t i = 0; i < m; i++) {
        if (!isfinite(rs[i]) || rs[i] < 0) {
            res->bad_patch = i / 3;
            st = bn_error_set(err, BN_ENUMERIC, "K is not finite and nonnegative: row of patch %zu (channel %c) sums to %g",
                              i / 3, "RGB"[i % 3], rs[i]);
            goto fail;
        }
        knorm = fmax(knorm, rs[i]);
    }
    res->k_norm_inf = knorm;
    const double *rho = bn_transport_rho(k);
    for (size_t i = 0; i < n; i++) {
        double fii = bn_transport_F(k, i, i);
        for (int c = 0; c < 3; c++) {
            diag[3 * i + (size_t)c] = rho[3 * i + (size_t)c] * fii;
            have_diag |= fii != 0;
        }
    }
    st = bn_solve_spectral_radius(k, o->power_iter, &res->spectral_radius, &res->spectral_radius_lower,
                                  &res->power_iterations, err);
    if (st != BN_OK)
        goto fail;
    gap = 1.0 - thr;
    if (res->spectral_radius_lower >= gap || (knorm >= gap && res->spectral_radius >= gap)) {
        res->reason = BN_STOP_SINGULAR;
        res->seconds_analyse = bn__now() - t0;
        st = bn_error_set(err, BN_ENUMERIC,
                          "I - K is singular within F's accuracy: ||K||_inf = %.9g and the spectral radius of K is "
                          "%.9g (at least %.9g), not below 1 - %g (the threshold: F's row sums are only known to "
                          "about that; the error bound delta/(1 - ||K||) would exceed 100%%). A closed scene with "
                          "reflectance 1 reflects light forever. Lower the reflectance, open the scene, or set the "
                          "threshold to F's row-sum error if you know it is smaller",
                          knorm, res->spectral_radius, res->spectral_radius_lower, thr);
        goto fail;
    }
    if (knorm >= 1)
        bn__note(o, BN_LOG_WARN,
                 "||K||_inf = %.9g >= 1 but the spectral radius is %.9g < 1: the iterations converge, but the a "
                 "priori bounds (bound, error_bound columns) do not apply",
                 knorm, res->spectral_radius);

    /* L0 = E;  r0 = E - (I - K) L0 = K E */
    memcpy(res->L, E, m * sizeof(double));
    bn_transport_apply(k, E, r);
    memset(&row, 0, sizeof row);
    bn__residual_norms(r, n, &row);
    r0max = row.residual_max;
    target = o->tol * res->norm_E;
    {
        double rate = res->spectral_radius, tgt = fmax(target, o->atol);
        if (stop == BN_SOLVE_STOP_BOUND && knorm < 1)
            tgt *= 1.0 - knorm;   /* ||r|| / (1 - ||K||) <= target */
        res->predicted_iterations = bn__predict(rate, r0max, tgt);
        if (type->sweeps == 2 && res->predicted_iterations != SIZE_MAX)
            res->predicted_iterations = (res->predicted_iterations + 1) / 2;
    }
    res->seconds_analyse = bn__now() - t0;
    if (res->predicted_iterations == SIZE_MAX)
        bn__note(o, BN_LOG_INFO, "spectral radius ~ %.9g (>= %.9g, %zu power steps); ||K||_inf = %.9g; the tolerance "
                 "cannot be predicted", res->spectral_radius, res->spectral_radius_lower, res->power_iterations, knorm);
    else
        bn__note(o, BN_LOG_INFO,
                 "spectral radius ~ %.9g (>= %.9g, %zu power steps); ||K||_inf = %.9g; predicted %zu %s to "
                 "tol %g (rate rho^k%s)",
                 res->spectral_radius, res->spectral_radius_lower, res->power_iterations, knorm,
                 res->predicted_iterations, o->method == BN_SOLVE_NEUMANN ? "bounces" : "iterations", o->tol,
                 o->method == BN_SOLVE_GAUSS_SEIDEL ? "; Gauss-Seidel needs at most this, often about half" : "");
    if (res->predicted_iterations != SIZE_MAX && res->predicted_iterations > o->max_iter && type->solve == NULL)
        bn__note(o, BN_LOG_WARN, "the predicted %zu iterations exceed --max-iter %zu: expect the iteration limit",
                 res->predicted_iterations, o->max_iter);
    bn__write_log_head(o, k, res, thr, stop);

    ctx.k = k;
    ctx.E = E;
    ctx.diag = have_diag ? diag : NULL;
    ctx.o = o;
    ctx.n = n;
    t1 = bn__now();

    if (type->solve) {
        /* ---- direct ---- */
        int singular = 0;
        st = type->solve(&ctx, res->L, &singular, err);
        if (st != BN_OK) {
            if (singular)
                res->reason = BN_STOP_SINGULAR;
            goto fail;
        }
        bad = bn__first_nonfinite(res->L, m);
        if (bad != SIZE_MAX) {
            res->bad_patch = bad / 3;
            res->reason = BN_STOP_DIVERGED_NAN;
            st = bn_error_set(err, BN_ENUMERIC, "direct solve: L of patch %zu (channel %c) is %g", bad / 3,
                              "RGB"[bad % 3], res->L[bad]);
            goto fail;
        }
        /* r <- E - (I - K) L */
        bn_transport_apply(k, res->L, rs);
        for (size_t i = 0; i < m; i++)
            r[i] = E[i] - res->L[i] + rs[i];
        bn__residual_norms(r, n, &row);
        row.iteration = 0;
        row.change = 0;
        row.bound = 0;
        row.error_bound = knorm < 1 ? row.residual_max / (1 - knorm) : INFINITY;
        row.seconds = bn__now() - t0;
        res->reason = BN_STOP_DIRECT;
        res->iterations = 0;
        bn__emit_row(o, &row, res->L);
    } else {
        /* ---- iterative: one driver for every method ---- */
        size_t it;
        double kpow = knorm;   /* ||K||^(s k + 1) */
        state = bn__calloc(1, type->state_size);
        if (!state) {
            st = bn_error_set(err, BN_ENOMEM, "solve: out of memory");
            goto fail;
        }
        st = type->setup(state, &ctx, res->L, r, err);
        state_ready = 1;
        if (st != BN_OK)
            goto fail;
        for (it = 0;; it++) {
            double measure;
            if (it > 0) {
                memcpy(Lprev, res->L, m * sizeof(double));
                if (!type->iterate(state, res->L, r)) {
                    /* r <- E - (I - K) L */
                    bn_transport_apply(k, res->L, rs);
                    for (size_t i = 0; i < m; i++)
                        r[i] = E[i] - res->L[i] + rs[i];
                }
                bn__residual_norms(r, n, &row);
                row.change = 0;
                for (size_t i = 0; i < m; i++)
                    row.change = fmax(row.change, fabs(res->L[i] - Lprev[i]));
                for (int s = 0; s < type->sweeps; s++)
                    kpow *= knorm;
            }
            row.iteration = it;
            row.bound = knorm < 1 ? kpow / (1 - knorm) * res->norm_E : INFINITY;
            row.error_bound = knorm < 1 ? row.residual_max / (1 - knorm) : INFINITY;
            row.seconds = bn__now() - t0;
            res->iterations = it;
            /* NaN / Inf: where did it first appear? */
            bad = bn__first_nonfinite(res->L, m);
            if (bad != SIZE_MAX || !isfinite(row.residual_max)) {
                if (bad == SIZE_MAX)
                    bad = bn__first_nonfinite(r, m);
                res->bad_patch = bad / 3;
                res->reason = BN_STOP_DIVERGED_NAN;
                st = bn_error_set(err, BN_ENUMERIC, "%s: iteration %zu produced a non-finite value at patch %zu (channel %c)",
                                  type->name, it, bad / 3, "RGB"[bad % 3]);
                goto fail;
            }
            if (bn__emit_row(o, &row, res->L)) {
                st = bn_error_set(err, BN_EINTR, "%s: stopped by the monitor at iteration %zu", type->name, it);
                goto fail;
            }
            /* stop test */
            measure = stop == BN_SOLVE_STOP_BOUND && knorm < 1 ? row.error_bound : row.residual_max;
            if (measure <= target) {
                res->reason = BN_STOP_CONVERGED_RTOL;
                break;
            }
            if (measure <= o->atol) {
                res->reason = BN_STOP_CONVERGED_ATOL;
                break;
            }
            if (row.residual_max > o->divergence * fmax(r0max, DBL_MIN) && o->divergence > 0) {
                res->reason = BN_STOP_DIVERGED_GROWTH;
                st = bn_error_set(err, BN_ENUMERIC, "%s diverged: residual %.6g at iteration %zu is %.3g times the initial %.6g",
                                  type->name, row.residual_max, it, row.residual_max / r0max, r0max);
                goto fail;
            }
            if (it >= o->max_iter) {
                res->reason = BN_STOP_MAX_ITER;
                st = bn_error_set(err, BN_ENOTCONV,
                                  "%s did not converge within %zu iterations: residual %.6g > %.6g (tol %g x ||E|| %.6g)%s",
                                  type->name, o->max_iter, row.residual_max, fmax(target, o->atol), o->tol, res->norm_E,
                                  res->predicted_iterations != SIZE_MAX ? "; raise --max-iter to the predicted count" : "");
                break;
            }
            if (bn_interrupted() != BN_OK) {
                st = bn_error_set(err, bn_interrupted(), "%s interrupted at iteration %zu", type->name, it);
                goto fail;
            }
        }
    }
    res->residual_max = row.residual_max;
    res->residual_rms = row.residual_rms;
    memcpy(res->residual_ch, row.residual_ch, sizeof row.residual_ch);
    res->change = row.change;
    res->error_bound = row.error_bound;
    res->seconds_iterate = bn__now() - t1;

    /* ---- the per-bounce terms K^0 E .. K^n E ---- */
    t1 = bn__now();
    if (o->bounces >= 0) {
        res->nterms = o->bounces + 1;
        res->terms = bn__calloc((size_t)res->nterms, sizeof(double *));
        if (!res->terms) {
            res->nterms = 0;
            st = bn_error_set(err, BN_ENOMEM, "solve: out of memory for %d bounce terms", o->bounces + 1);
            goto fail;
        }
        for (int q = 0; q < res->nterms; q++)
            if (!(res->terms[q] = bn__malloc_array(m ? m : 1, sizeof(double)))) {
                st = bn_error_set(err, BN_ENOMEM, "solve: out of memory for %d bounce terms of %zu patches",
                                  o->bounces + 1, n);
                goto fail;
            }
        bn_solve_terms(k, E, res->nterms, res->terms);
    }
    res->seconds_terms = bn__now() - t1;
    res->seconds = bn__now() - t0;
    if (state_ready)
        type->cleanup(state);
    free(state);
    free(ones);
    free(rs);
    free(diag);
    free(r);
    free(Lprev);
    return st;

fail:
    if (state_ready)
        type->cleanup(state);
    free(state);
    free(ones);
    free(rs);
    free(diag);
    free(r);
    free(Lprev);
    /* No NaN and no half answer leaves a failed solve: L and the terms are released. */
    free(res->L);
    res->L = NULL;
    if (res->terms)
        for (int q = 0; q < res->nterms; q++)
            free(res->terms[q]);
    free(res->terms);
    res->terms = NULL;
    res->nterms = 0;
    res->seconds = bn__now() - t0;
    return st;
}
