/* The study's CSV (with its provenance) and its readable summary. */
#include "study/study_internal.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

static void bn__num(FILE *fp, double v)
{
    if (isnan(v))
        fputs("nan", fp);
    else if (isinf(v))
        fputs(v > 0 ? "inf" : "-inf", fp);
    else
        fprintf(fp, "%.9g", v);
}

/* Column names keep [A-Za-z0-9_] only. */
static void bn__colname(FILE *fp, const char *s)
{
    for (; *s; s++)
        fputc((*s >= 'a' && *s <= 'z') || (*s >= 'A' && *s <= 'Z') || (*s >= '0' && *s <= '9') ? *s : '_', fp);
}

/* The CSV's comment lines: provenance, the reference, norms, the equal-error figures, units. */
static void bn__study_csv_head(const bn_study_result *r, const char *provenance, FILE *fp)
{
    if (provenance && *provenance) {
        fputs(provenance, fp);
        if (provenance[strlen(provenance) - 1] != '\n')
            fputc('\n', fp);
    }
    fprintf(fp, "# study=%s\n# reference=%s\n# reference_patches=%zu\n# reference_seconds=%.6g\n",
            bn_study_param_name(r->param), r->reference, r->ref_patches, r->ref_seconds);
    if (isfinite(r->ref_order))
        fprintf(fp, "# reference_order=%.4g\n# reference_error_unextrapolated=%.6g\n", r->ref_order, r->ref_error_raw);
    fprintf(fp, "# reference_error=%.6g\n# reference_error_patch=%.6g\n# reference_error_how=%s\n", r->ref_error,
            r->ref_error_patch, r->ref_error_how);
    fprintf(fp, "# norm_E=%.9g\n# norm_L=%.9g\n", r->norm_E, r->norm_L);
    for (size_t s = 0; r->ref_surface_mean && s < r->nsurfaces; s++) {
        fputs("# reference_mean_", fp);
        bn__colname(fp, r->surface[s]);
        fprintf(fp, "=%.9g %.9g %.9g\n", r->ref_surface_mean[3 * s], r->ref_surface_mean[3 * s + 1],
                r->ref_surface_mean[3 * s + 2]);
    }
    if (r->param == BN_STUDY_BOUNCES || r->param == BN_STUDY_MAX_ITER || r->param == BN_STUDY_TOL)
        fprintf(fp, "# k_norm_inf=%.9g\n# spectral_radius=%.9g\n", r->k_norm, r->spectral_radius);
    if (!isnan(r->t_radiosity) || !isnan(r->t_trace) || !isnan(r->best_trace))
        fprintf(fp, "# target=%.6g\n# target_metric=%s\n# seconds_radiosity=%.6g\n# seconds_trace=%.6g\n"
                    "# ratio_trace_over_radiosity=%.6g\n",
                r->target, r->metric_patch ? "err_rms_rel" : "err_surface_max", r->t_radiosity, r->t_trace, r->ratio);
    if (!isnan(r->fine_target))
        fprintf(fp, "# fine_target=%.6g\n# seconds_radiosity_fine=%.6g\n# seconds_trace_fine=%.6g\n"
                    "# ratio_trace_over_radiosity_fine=%.6g\n",
                r->fine_target, r->t_radiosity_fine, r->t_trace_fine, r->ratio_fine);
    fprintf(fp, "# units: err_inf W m^-2 sr^-1; err_* relative; bound and estimate W m^-2 sr^-1; t_* seconds; "
                "peak_mb MiB; ground 0 same mesh, 1 reference patches by centroid, 2 area means of the setting's "
                "patches over each reference patch\n");
}

/* Row w of the CSV. */
static void bn__study_csv_row(const bn_study_result *r, const bn_study_row *w, FILE *fp)
{
    const double v[] = {w->err_inf, w->err_inf_rel, w->err_max_rel, w->err_rms_rel, w->err_l1_rel, w->err_energy_rel,
                        w->err_surface_max, w->err_surface_mean, w->bound, w->bound_ke, w->estimate, w->t_mesh, w->t_ff,
                        w->t_solve, w->t_output, w->t_total, w->peak_mb, w->k_norm, w->se_surface_max, w->t_iterate,
                        (double)w->k_entries, w->k_mb};
    fprintf(fp, "%s,%s,%s,", bn_study_param_name(r->param), w->method, w->value);
    bn__num(fp, w->x);
    fprintf(fp, ",%zu,", w->patches);
    if (w->iterations == SIZE_MAX)
        fputs("nan", fp);
    else
        fprintf(fp, "%zu", w->iterations);
    fprintf(fp, ",%d", w->ground);
    for (size_t k = 0; k < sizeof v / sizeof v[0]; k++) {
        fputc(',', fp);
        bn__num(fp, v[k]);
    }
    for (size_t s = 0; s < r->nsurfaces; s++) {
        fputc(',', fp);
        bn__num(fp, w->err_surface[s]);
    }
    fputc('\n', fp);
}

bn_status bn_study_write_csv(const bn_study_result *r, const char *path, const char *provenance, bn_error *err)
{
    bn__outfile f;
    bn_status st = bn__outfile_open(&f, path, "w", err);
    if (st != BN_OK)
        return st;
    bn__study_csv_head(r, provenance, f.fp);
    fputs(BN_STUDY_CSV_COLUMNS, f.fp);
    for (size_t s = 0; s < r->nsurfaces; s++) {
        fputs(",err_surf_", f.fp);
        bn__colname(f.fp, r->surface[s]);
    }
    fputc('\n', f.fp);
    for (size_t i = 0; i < r->nrows; i++)
        bn__study_csv_row(r, &r->rows[i], f.fp);
    return bn__outfile_commit(&f, err);
}

/* The printed table's header line. */
static void bn__study_print_header(const bn_study_result *r, FILE *fp)
{
    fprintf(fp, "study        %s\n", bn_study_param_name(r->param));
    fprintf(fp, "reference    %s (%.3g s)\n", r->reference, r->ref_seconds);
    fprintf(fp, "ref. error   %.3g per surface, %.3g per patch (relative): %s\n", r->ref_error, r->ref_error_patch,
            r->ref_error_how);
    if (r->param == BN_STUDY_BOUNCES || r->param == BN_STUDY_MAX_ITER || r->param == BN_STUDY_TOL)
        fprintf(fp, "operator     ||K||_inf = %.6g, spectral radius ~ %.6g, ||E||_inf = %.6g, ||L||_inf = %.6g\n",
                r->k_norm, r->spectral_radius, r->norm_E, r->norm_L);
    fprintf(fp, "\n%-13s %-10s %7s %6s %10s %10s %10s %10s %10s %10s", "method", "value", "patches", "iter", "err_surf",
            "err_patch", "err_rms", "err_power", "t_solve_s", "t_total_s");
    if (r->param == BN_STUDY_BOUNCES || r->param == BN_STUDY_MAX_ITER)
        fprintf(fp, " %10s %10s %9s %9s %9s", "err_inf", "bound", "bound/err", "bKE/err", "est/err");
    else
        fprintf(fp, " %8s %10s %8s", "peak_MiB", "K_entries", "K_MiB");
    fputc('\n', fp);
}

/* Row w; with the bounds' columns, the truncated rows' bound / error ratios widen [b[0], b[1]] (from
 * ||E||) and [b[2], b[3]] (from ||KE||). */
static void bn__study_print_row(const bn_study_row *w, int bound_cols, double b[4], FILE *fp)
{
    char it[24];
    if (w->iterations == SIZE_MAX)
        snprintf(it, sizeof it, "-");
    else
        snprintf(it, sizeof it, "%zu", w->iterations);
    fprintf(fp, "%-13s %-10s %7zu %6s %10.3g %10.3g %10.3g %10.3g %10.4g %10.4g", w->method, w->value, w->patches, it,
            w->err_surface_max, w->err_max_rel, w->err_rms_rel, w->err_energy_rel, w->t_solve, w->t_total);
    if (bound_cols) {
        double ratio = w->err_inf > 0 ? w->bound / w->err_inf : NAN;
        double r2 = w->err_inf > 0 ? w->bound_ke / w->err_inf : NAN;
        fprintf(fp, " %10.3g %10.3g %9.3g %9.3g %9.3g", w->err_inf, w->bound, ratio, r2,
                w->err_inf > 0 ? w->estimate / w->err_inf : NAN);
        if (isfinite(ratio) && strcmp(w->method, "truncated") == 0) {
            b[0] = fmin(b[0], ratio);
            b[1] = fmax(b[1], ratio);
            b[2] = fmin(b[2], r2);
            b[3] = fmax(b[3], r2);
        }
    } else
        fprintf(fp, " %8.1f %10zu %8.1f", w->peak_mb, w->k_entries, w->k_mb);
    fputc('\n', fp);
}

static void bn__print_time_or_not(FILE *fp, double t)
{
    if (isnan(t))
        fprintf(fp, "not reached");
    else
        fprintf(fp, "%.4g s", t);
}

/* The equal-error lines: each side's time to the target, and to 3x the reference's own error. */
static void bn__study_print_equal_error(const bn_study_result *r, FILE *fp)
{
    fprintf(fp, "\nequal error  target %.3g %s (reference's own ~%.3g)\n", r->target,
            r->metric_patch ? "RMS relative error per patch, on the reference's patches" : "per-surface relative error",
            r->metric_patch ? r->ref_error_patch : r->ref_error);
    fprintf(fp, "  radiosity  ");
    bn__print_time_or_not(fp, r->t_radiosity);
    fprintf(fp, " (best %.3g)\n", r->best_radiosity);
    fprintf(fp, "  tracer     ");
    bn__print_time_or_not(fp, r->t_trace);
    fprintf(fp, " (best %.3g)\n", r->best_trace);
    if (!isnan(r->ratio))
        fprintf(fp, "  ratio      the tracer takes %.3g times as long as radiosity\n", r->ratio);
    if (!isnan(r->fine_target)) {
        fprintf(fp, "  finest     %.3g (3x the reference's own error): radiosity ", r->fine_target);
        bn__print_time_or_not(fp, r->t_radiosity_fine);
        fprintf(fp, ", tracer ");
        bn__print_time_or_not(fp, r->t_trace_fine);
        if (!isnan(r->ratio_fine))
            fprintf(fp, ", ratio %.3g", r->ratio_fine);
        fputc('\n', fp);
    }
}

void bn_study_print(const bn_study_result *r, FILE *fp)
{
    int bounces = r->param == BN_STUDY_BOUNCES, bound_cols = bounces || r->param == BN_STUDY_MAX_ITER;
    double b[4] = {INFINITY, 0, INFINITY, 0};
    bn__study_print_header(r, fp);
    for (size_t i = 0; i < r->nrows; i++)
        bn__study_print_row(&r->rows[i], bound_cols, b, fp);
    if (bounces && b[1] > 0)
        fprintf(fp, "\nbound        the a priori bound ||K||^(n+1)/(1-||K||) ||E|| is %.3g to %.3g times the measured "
                    "||L - S_n||_inf (>= 1 everywhere means it held)\n", b[0], b[1]);
    if (bounces && b[3] > 0)
        fprintf(fp, "             from the first reflection, ||K||^n/(1-||K||) ||KE||, it is %.3g to %.3g times; the "
                    "looseness grows like (||K||_inf / rho(K))^n = (%.4g / %.4g)^n\n", b[2], b[3], r->k_norm,
                r->spectral_radius);
    if (!isnan(r->best_trace) || !isnan(r->best_radiosity))
        bn__study_print_equal_error(r, fp);
}
