/* bounce: solving (I - K) L = E per channel by Jacobi, Gauss-Seidel, the truncated Neumann series
 * and a direct LAPACK solve; one driver, one monitor, stop reasons (PETSc's KSP shape). */
#ifndef BOUNCE_SOLVE_H
#define BOUNCE_SOLVE_H

#include <stddef.h>
#include <stdio.h>
#include "bounce/transport.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum bn_solve_method { BN_SOLVE_JACOBI, BN_SOLVE_GAUSS_SEIDEL, BN_SOLVE_NEUMANN, BN_SOLVE_DIRECT } bn_solve_method;
const char *bn_solve_method_name(bn_solve_method m);   /* "jacobi", "gauss-seidel", "neumann", "direct" */
const char *bn_solve_method_names(void);               /* "jacobi|gauss-seidel|neumann|direct" */
int bn_solve_method_parse(const char *name, bn_solve_method *m);   /* 0, or -1 for no such method */
/* 1 when operator k offers what the method needs (Gauss-Seidel rows, the direct solve entries):
 * the one rule by which a front end replaces a method the operator cannot run (with Jacobi). */
int bn_solve_method_runs_on(bn_solve_method m, const bn_transport *k);

/* Why a solve stopped. Stopping is a reason, not an error (PETSc's KSPConvergedReason). */
typedef enum bn_stop_reason {
    BN_STOP_NONE,
    BN_STOP_CONVERGED_RTOL,   /* ||r||_inf <= tol * ||E||_inf (or the series tail bound is) */
    BN_STOP_CONVERGED_ATOL,   /* ||r||_inf <= atol */
    BN_STOP_DIRECT,           /* direct solve done */
    BN_STOP_MAX_ITER,         /* iteration limit reached first */
    BN_STOP_DIVERGED_NAN,
    BN_STOP_DIVERGED_GROWTH,
    BN_STOP_SINGULAR          /* ||K|| >= 1 - threshold: I - K is (near) singular */
} bn_stop_reason;
const char *bn_stop_reason_name(bn_stop_reason r);

/* What the stop test compares with tol * ||E||_inf (and atol). */
typedef enum bn_solve_stop {
    BN_SOLVE_STOP_DEFAULT,    /* residual for jacobi and gauss-seidel, bound for neumann */
    BN_SOLVE_STOP_RESIDUAL,   /* ||E - (I - K) L||_inf */
    BN_SOLVE_STOP_BOUND,      /* the a posteriori error bound ||r||_inf / (1 - ||K||_inf): a guarantee
                                 on ||L - L*||_inf (the series' tail bound); falls back to the residual
                                 when ||K||_inf >= 1 */
    BN_SOLVE_STOP_PATCH       /* every patch's own: max_i,c |r_ic| / |L_ic| <= tol (entries with
                                 |r_ic| <= atol count as met). For emission over many orders of
                                 magnitude: a dim light's region is solved to tol of its own
                                 radiance, where tol ||E||_inf may exceed that radiance itself */
} bn_solve_stop;
const char *bn_solve_stop_name(bn_solve_stop v);
const char *bn_solve_stop_names(void);   /* "default|residual|bound|patch" */
int bn_solve_stop_parse(const char *s, bn_solve_stop *out);   /* 0, or -1 for no such name */

/* One row of the convergence table, handed to the monitor after every iteration (row 0 is the
 * initial guess L0 = E, before any sweep). Norms are infinity norms over patches. */
typedef struct bn_solve_row {
    size_t iteration;
    double residual_max;      /* ||E - (I - K) L||_inf over all channels */
    double residual_rms;      /* RMS over all N*3 entries */
    double residual_ch[3];    /* per channel max */
    double change;            /* ||L_k - L_(k-1)||_inf (0 at row 0) */
    double bound;             /* a priori ||K||^(s k + 1) / (1 - ||K||) ||E|| (s sweeps per iteration);
                                 inf when ||K||_inf >= 1 */
    double error_bound;       /* a posteriori ||r||_inf / (1 - ||K||_inf) >= ||L - L*||_inf; inf if ||K|| >= 1 */
    double seconds;           /* since the solve started */
} bn_solve_row;
/* Called after every row; L (N*3) is borrowed for the call only. A nonzero return stops the
 * solve (reason BN_STOP_NONE, status BN_EINTR). */
typedef int (*bn_solve_monitor_fn)(void *user, const bn_solve_row *row, const double *L);

typedef struct bn_solve_opts {
    bn_solve_method method;   /* default gauss-seidel */
    double tol;               /* relative to ||E||_inf over all channels (default 1e-6) */
    double atol;              /* absolute (default 0) */
    size_t max_iter;          /* default 100000 */
    int    symmetric;         /* Gauss-Seidel: forward then backward sweep */
    int    bounces;           /* keep K^0 E .. K^bounces E separately (default 3; at most
                                 BN_SOLVE_MAX_BOUNCES); < 0: none */
    FILE  *log;               /* convergence table (CSV), NULL for none */
    const char *log_header;   /* `# key=value` lines written before the table (provenance) */
    int    quiet;
    /* Added by the solver issue: */
    bn_solve_stop stop;       /* default BN_SOLVE_STOP_DEFAULT */
    double singular_threshold;/* refuse when the spectral radius (lower bound) or ||K||_inf with it
                                 is >= 1 - threshold (default 1e-6: above the row-sum error of F
                                 stored in float, 2^-24 per entry, ~6e-8 per row; raise it to the
                                 row-sum error delta of F when F is less accurate: a solve with
                                 1 - ||K|| < delta has an error bound delta / (1 - ||K||) above 100%) */
    double divergence;        /* diverged (growth) when residual > divergence * initial (default 1e5) */
    size_t power_iter;        /* power-iteration steps for the spectral radius, at most (default 100) */
    size_t max_memory;        /* direct: bytes allowed for the dense copy; 0 = 80% of physical memory */
    bn_solve_monitor_fn monitor;  /* NULL: none (the CSV log is written anyway when log is set) */
    void  *monitor_user;
    bn_log log_sink;          /* notes (prediction, warnings); NULL fn: warnings to stderr */
    int    threads;           /* for K's applications; 0 = the caller's; results do not depend on it */
    /* The radiance that light from punctual lights gives the patches where it arrives directly (N x 3,
     * rho E_direct / pi; NULL: none): part of the source (L = E + direct + K L) but of bounce 1, not 0
     * (a point light is not seen): the terms are E, K E + direct, K (K E + direct), ... */
    const double *direct;
    /* N*3 or NULL: the power iteration's start and its last iterate (bn_solve_spectral_radius_from);
     * bn_pipeline keeps one across relights, where K changes little. */
    double *power_start;
    /* 1: Jacobi and Neumann with ||K||_inf < 1 - singular_threshold and no log (the spectral radius then
     * decides nothing: the singularity check and the bounds rest on ||K||_inf) skip the power iteration
     * before the solve (no predicted count) and read the spectral radius from their own residuals after
     * it (r_k = K^k r_0 with r_0 >= 0: sqrt(max r_k / max r_(k-2)) per channel, when the last two agree
     * within 1%; spectral_radius_lower 0, power_iterations 0), leaving the last residual in power_start;
     * else (a start near the answer, few iterations) the power iteration after the solve. For relights
     * (bn_pipeline_relight), where the power steps were 40% of the time. */
    int power_lazy;
} bn_solve_opts;
void bn_solve_opts_default(bn_solve_opts *o);
/* Each term is a whole N x 3 vector (and an image layer, a bake attribute): past this many, the
 * series' tail belongs in `rest`, which L - sum of the terms gives at no cost. */
#define BN_SOLVE_MAX_BOUNCES 1000
/* Every option in range (tol and atol finite and >= 0 (both 0: run to max_iter); max_iter >= 1; bounces at most
 * BN_SOLVE_MAX_BOUNCES; threads >= 0; thresholds in range): BN_EUSAGE naming the option by its field
 * name and its value, else BN_OK. bn_solve calls it first; front ends may call it before any work. */
bn_status bn_solve_opts_check(const bn_solve_opts *o, bn_error *err);

typedef struct bn_solve_result {
    size_t n;                 /* patches */
    double *L;                /* N*3: the solution (owned) */
    int     nterms;           /* terms kept: K^0 E .. K^(nterms-1) E */
    double **terms;           /* nterms arrays of N*3 (owned) */
    bn_stop_reason reason;
    size_t iterations;
    double residual_max, residual_rms;   /* final ||E - (I - K) L|| (inf and RMS over all entries) */
    double norm_E;            /* ||E||_inf */
    double k_norm_inf;        /* ||K||_inf */
    double spectral_radius;   /* power-iteration estimate of rho(K) */
    size_t predicted_iterations;  /* from the spectral radius, before iterating */
    double seconds;
    /* Added by the solver issue: */
    bn_solve_method method;
    double spectral_radius_lower; /* Collatz-Wielandt lower bound from the power iteration (rigorous) */
    size_t power_iterations;      /* steps the estimate took */
    double residual_ch[3];        /* final per-channel max residual */
    double change;                /* last ||L_k - L_(k-1)||_inf */
    double error_bound;           /* a posteriori ||r|| / (1 - ||K||) (inf if ||K||_inf >= 1) */
    double seconds_analyse;       /* norms, power iteration, checks */
    double seconds_iterate;       /* the iterations (or the factorisation for direct) */
    double seconds_terms;         /* the per-bounce terms K^k E */
    size_t bad_patch;             /* NaN/Inf: the first patch where it appeared (else SIZE_MAX) */
} bn_solve_result;

/* Solves (I - K) L = E. E: N*3 (borrowed). Fills *res (free with bn_solve_result_free). Returns
 * BN_OK when converged, BN_ENOTCONV at the iteration limit (L and the terms are kept),
 * BN_ENUMERIC when diverged or singular (res->reason says which), BN_ENOTSUP when K cannot serve
 * the method (Gauss-Seidel needs rows, direct needs entries), BN_EINTR/BN_ETERM when interrupted,
 * or the status of a failed application of K. On any failure but BN_ENOTCONV, res holds no L. */
bn_status bn_solve(const bn_transport *k, const double *E, const bn_solve_opts *o, bn_solve_result *res,
                   bn_error *err);
void bn_solve_result_free(bn_solve_result *res);

/* Bytes the direct solve needs for its dense double copy of I - K (N^2 * 8 + pivots). */
size_t bn_solve_direct_bytes(size_t n);

/* Power iteration on each channel's K_c = diag(rho_c) F from x = 1: *estimate = the largest over
 * channels of sqrt(||K_c^2 x|| / ||x||) (the geometric mean of the last two steps' ratios: the one-step
 * ratio alternates when an eigenvalue near -rho exists, as in a cavity between facing surfaces) once
 * it settles (within 1e-3 (1 - estimate) of its values one and two steps before) or after max_steps;
 * *lower = the Collatz-Wielandt bound max_c min_i (K_c x)_i / x_i <= spectral radius (x >= 0). */
bn_status bn_solve_spectral_radius(const bn_transport *k, size_t max_steps, double *estimate, double *lower,
                                   size_t *steps, bn_error *err);
/* The same from a start of the caller's: x (N*3, in/out) when it holds a positive value in every channel,
 * plus 1e-3 of its largest (every entry positive), else from 1; its last iterate is left in x. A solve
 * after a small change of K (a relight) starts near the dominant eigenvector and settles in a few
 * steps. */
bn_status bn_solve_spectral_radius_from(const bn_transport *k, size_t max_steps, double *x, double *estimate,
                                        double *lower, size_t *steps, bn_error *err);

/* Fills terms[k] = K^k E for k = 0..nterms-1 (caller-allocated, N*3 each); stops with the
 * operator's status if an application of K fails. */
bn_status bn_solve_terms(const bn_transport *k, const double *E, int nterms, double **terms, bn_error *err);
/* The same with the punctual lights' direct radiance D (NULL: none) in bounce 1: terms[0] = E,
 * terms[1] = K E + D, terms[k] = K terms[k-1]. */
bn_status bn_solve_terms_direct(const bn_transport *k, const double *E, const double *D, int nterms, double **terms,
                                bn_error *err);

/* The column names of the convergence table. */
#define BN_SOLVE_LOG_COLUMNS "iteration,residual_max,residual_rms,residual_max_R,residual_max_G,residual_max_B,change,bound,error_bound,seconds"

#ifdef __cplusplus
}
#endif
#endif
