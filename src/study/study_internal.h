/* Internals of the study module: the reference solution and the common-ground comparison. */
#ifndef BOUNCE_STUDY_INTERNAL_H
#define BOUNCE_STUDY_INTERNAL_H

#include "bounce/study.h"

/* A solution on one mesh, with what the comparison needs precomputed. */
typedef struct bn__study_ref {
    const bn_scene *scene;   /* borrowed */
    size_t n, nsurf;
    const double *L;         /* N*3, borrowed */
    double *E;               /* N*3 (owned) */
    double *surf_mean;       /* nsurf*3 area-weighted means (owned) */
    double power[3];         /* reflected power pi sum A (L - E), W */
    double norm_L;           /* ||L||_inf */
    double floor[3];         /* per-patch relative errors divide by max(|L_ref|, floor): the
                                area-weighted mean radiance per channel */
} bn__study_ref;

bn_status bn__study_ref_init(bn__study_ref *r, const bn_scene *s, const double *L, size_t nsurf, bn_error *err);
void bn__study_ref_free(bn__study_ref *r);

/* Area-weighted mean of L per surface (material): out nsurf*3. */
void bn__study_surface_means(const bn_scene *s, const double *L, size_t nsurf, double *out);
/* pi sum_i A_i (L_i - E_i) per channel, A in m^2. */
void bn__study_reflected_power(const bn_scene *s, const double *L, const double *E, double out[3]);

/* Fills the err_* fields of row (err_surface must hold ref->nsurf doubles) for the solution L on
 * scene s against the reference. Same mesh (ground 0) when s has the reference's patches, else each
 * reference patch takes the value of the patch of s in its face containing its centroid (ground 1). */
bn_status bn__study_compare(const bn__study_ref *ref, const bn_scene *s, const double *L, bn_study_row *row,
                            bn_error *err);

/* The solution L on scene s seen on the reference mesh: out[3i+c] = L of the patch of s holding
 * reference patch i's centroid (in the same face). out: 3 N_ref. */
bn_status bn__study_map_onto(const bn_scene *ref, const bn_scene *s, const double *L, double *out, bn_error *err);

/* One plot panel (0: error against time, 1: error against the varied parameter) as SVG text
 * (malloc'd), for the HTML report; drawn through a temporary file beside `beside`. */
bn_status bn__study_panel_svg(const bn_study_result *r, int which, const char *beside, char **svg, bn_error *err);

/* Peak resident memory: reset the high-water mark (Linux clear_refs; no-op elsewhere), read it in MiB. */
void bn__study_peak_reset(void);
double bn__study_peak_mb(void);

#endif
