/* Errors on common ground: per patch (same mesh; the reference's patches by centroid lookup in a
 * coarser setting; area means of a finer setting's patches over each reference patch),
 * per surface (area-weighted means per material) and in the total reflected power. */
#include "study/study_internal.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

void bn__study_peak_reset(void)
{
    /* Writing 5 to clear_refs resets VmHWM to the current RSS (Linux >= 4.0). */
    FILE *f = fopen("/proc/self/clear_refs", "w");
    if (f) {
        fputs("5", f);
        fclose(f);
    }
}

double bn__study_peak_mb(void)
{
    FILE *f = fopen("/proc/self/status", "r");
    char line[256];
    double kb = NAN;
    if (!f)
        return NAN;
    while (fgets(line, sizeof line, f))
        if (strncmp(line, "VmHWM:", 6) == 0) {
            kb = strtod(line + 6, NULL);
            break;
        }
    fclose(f);
    return kb / 1024.0;
}

void bn__study_surface_means(const bn_scene *s, const double *L, size_t nsurf, double *out)
{
    size_t n;
    const bn_patch *p = bn_scene_patches(s, &n);
    double *area = bn__calloc(nsurf ? nsurf : 1, sizeof(double));
    memset(out, 0, nsurf * 3 * sizeof(double));
    if (!area)
        return;
    for (size_t i = 0; i < n; i++) {
        size_t m = p[i].material;
        if (m >= nsurf)
            continue;
        area[m] += p[i].area;
        for (int c = 0; c < 3; c++)
            out[3 * m + (size_t)c] += p[i].area * L[3 * i + (size_t)c];   /* sum A_i L_i */
    }
    for (size_t m = 0; m < nsurf; m++)
        for (int c = 0; c < 3; c++)
            out[3 * m + (size_t)c] = area[m] > 0 ? out[3 * m + (size_t)c] / area[m] : 0;
    free(area);
}

void bn__study_reflected_power(const bn_scene *s, const double *L, const double *E, double out[3])
{
    double e[3];
    bn_scene_power(s, L, out);   /* P = pi sum_i A_i (L_i - E_i) */
    bn_scene_power(s, E, e);
    for (int c = 0; c < 3; c++)
        out[c] -= e[c];
}

bn_status bn__study_ref_init(bn__study_ref *r, const bn_scene *s, const double *L, size_t nsurf, bn_error *err)
{
    memset(r, 0, sizeof *r);
    r->scene = s;
    bn_scene_patches(s, &r->n);
    r->nsurf = nsurf;
    r->L = L;
    r->E = bn__malloc_array(3 * r->n + 1, sizeof(double));
    r->surf_mean = bn__malloc_array(3 * nsurf + 1, sizeof(double));
    if (!r->E || !r->surf_mean) {
        bn__study_ref_free(r);
        return bn_error_set(err, BN_ENOMEM, "study: out of memory for the reference (%zu patches)", r->n);
    }
    bn_scene_patch_emission(s, r->E);
    bn__study_surface_means(s, L, nsurf, r->surf_mean);
    bn__study_reflected_power(s, L, r->E, r->power);
    for (size_t i = 0; i < 3 * r->n; i++)
        r->norm_L = fmax(r->norm_L, fabs(L[i]));
    {
        const bn_patch *p = bn_scene_patches(s, &r->n);
        double a = 0, m[3] = {0, 0, 0};
        for (size_t i = 0; i < r->n; i++) {
            a += p[i].area;
            for (int c = 0; c < 3; c++)
                m[c] += p[i].area * fabs(L[3 * i + (size_t)c]);
        }
        for (int c = 0; c < 3; c++)
            r->floor[c] = a > 0 && m[c] > 0 ? m[c] / a : 1e-300;
    }
    return BN_OK;
}

void bn__study_ref_free(bn__study_ref *r)
{
    free(r->E);
    free(r->surf_mean);
    memset(r, 0, sizeof *r);
}

/* Is x (in the patch's plane) inside the convex patch? Edges tested with a tolerance relative to
 * the edge length, so centroids on a shared edge still find a patch. */
static int bn__inside(const double *pv, const bn_patch *p, const double x[3])
{
    for (unsigned k = 0; k < p->ncorners; k++) {
        const double *a = pv + 3 * p->corner[k], *b = pv + 3 * p->corner[(k + 1) % p->ncorners];
        double e[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, d[3] = {x[0] - a[0], x[1] - a[1], x[2] - a[2]};
        double cr[3] = {e[1] * d[2] - e[2] * d[1], e[2] * d[0] - e[0] * d[2], e[0] * d[1] - e[1] * d[0]};
        double side = cr[0] * p->normal[0] + cr[1] * p->normal[1] + cr[2] * p->normal[2];
        double len2 = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
        if (side < -1e-9 * len2)   /* (e x d) . n < 0: x is right of the edge, outside */
            return 0;
    }
    return 1;
}

/* map[i] = the patch of s holding reference patch i's centroid (in the same face). */
static bn_status bn__lookup(const bn_scene *ref, const bn_scene *s, size_t *map, bn_error *err)
{
    size_t nr, ns, nfr, nfs, nv;
    const bn_patch *pr = bn_scene_patches(ref, &nr), *ps = bn_scene_patches(s, &ns);
    const double *pv = bn_scene_patch_vertices(s, &nv);
    size_t *start, *order;
    bn_scene_faces(ref, &nfr);
    bn_scene_faces(s, &nfs);
    if (nfr != nfs)
        return bn_error_set(err, BN_EINTERNAL, "study: the reference has %zu faces, the setting %zu", nfr, nfs);
    start = bn__calloc(nfs + 1, sizeof(size_t));
    order = bn__malloc_array(ns + 1, sizeof(size_t));
    if (!start || !order) {
        free(start);
        free(order);
        return bn_error_set(err, BN_ENOMEM, "study: out of memory for the centroid lookup");
    }
    for (size_t j = 0; j < ns; j++)   /* patches bucketed by face (counting sort) */
        start[ps[j].face + 1]++;
    for (size_t f = 0; f < nfs; f++)
        start[f + 1] += start[f];
    {
        size_t *fill = bn__calloc(nfs + 1, sizeof(size_t));
        if (!fill) {
            free(start);
            free(order);
            return bn_error_set(err, BN_ENOMEM, "study: out of memory for the centroid lookup");
        }
        for (size_t j = 0; j < ns; j++)
            order[start[ps[j].face] + fill[ps[j].face]++] = j;
        free(fill);
    }
    for (size_t i = 0; i < nr; i++) {
        size_t f = pr[i].face, best = SIZE_MAX;
        double bestd = INFINITY;
        for (size_t q = start[f]; q < start[f + 1]; q++) {
            size_t j = order[q];
            double d2 = 0;
            if (bn__inside(pv, &ps[j], pr[i].centroid)) {
                best = j;
                break;
            }
            for (int c = 0; c < 3; c++)
                d2 += (ps[j].centroid[c] - pr[i].centroid[c]) * (ps[j].centroid[c] - pr[i].centroid[c]);
            if (d2 < bestd) {   /* fallback: the nearest centroid in the face */
                bestd = d2;
                best = j;
            }
        }
        if (best == SIZE_MAX) {
            free(start);
            free(order);
            return bn_error_set(err, BN_EINTERNAL, "study: face %zu has no patch in the setting's mesh", f);
        }
        map[i] = best;
    }
    free(start);
    free(order);
    return BN_OK;
}

bn_status bn__study_map_onto(const bn_scene *ref, const bn_scene *s, const double *L, double *out, bn_error *err)
{
    size_t nr, ns;
    size_t *map;
    bn_status st;
    bn_scene_patches(ref, &nr);
    bn_scene_patches(s, &ns);
    if (ref == s) {
        memcpy(out, L, 3 * nr * sizeof(double));
        return BN_OK;
    }
    map = bn__malloc_array(nr + 1, sizeof(size_t));
    if (!map)
        return bn_error_set(err, BN_ENOMEM, "study: out of memory mapping %zu patches", nr);
    st = bn__lookup(ref, s, map, err);
    for (size_t i = 0; st == BN_OK && i < nr; i++)
        memcpy(out + 3 * i, L + 3 * map[i], 3 * sizeof(double));
    free(map);
    return st;
}

static int bn__same_mesh(const bn_scene *a, const bn_scene *b)
{
    size_t na, nb;
    const bn_patch *pa = bn_scene_patches(a, &na), *pb = bn_scene_patches(b, &nb);
    if (a == b)
        return 1;
    if (na != nb)
        return 0;
    for (size_t i = 0; i < na; i++)
        if (pa[i].face != pb[i].face || memcmp(pa[i].centroid, pb[i].centroid, sizeof pa[i].centroid) != 0)
            return 0;
    return 1;
}

/* A finer setting read as what it says about each reference patch: the area mean of its patches
 * whose centroids fall in it (a point value at the reference's centroid would add the variation
 * across the coarse patch as error). Reference patches no centroid falls in keep the centroid
 * lookup map. *avg: 4 nr values (R, G, B, area), malloc'd. */
static bn_status bn__area_means(const bn__study_ref *ref, const bn_scene *s, const double *L, const size_t *map,
                                double **avg, bn_error *err)
{
    size_t ns, nr = ref->n;
    const bn_patch *ps = bn_scene_patches(s, &ns);
    size_t *back = bn__malloc_array(ns + 1, sizeof(size_t));
    double *acc = bn__calloc(4 * nr + 1, sizeof(double));
    bn_status st = back && acc ? bn__lookup(s, ref->scene, back, err)
                               : bn_error_set(err, BN_ENOMEM, "study: out of memory comparing %zu patches", ns);
    if (st != BN_OK) {
        free(back);
        free(acc);
        return st;
    }
    for (size_t j = 0; j < ns; j++) {
        double *a = acc + 4 * back[j];
        a[3] += ps[j].area;
        for (int c = 0; c < 3; c++)
            a[c] += ps[j].area * L[3 * j + (size_t)c];
    }
    for (size_t i = 0; i < nr; i++)
        for (int c = 0; c < 3; c++)
            acc[4 * i + (size_t)c] = acc[4 * i + 3] > 0 ? acc[4 * i + (size_t)c] / acc[4 * i + 3]
                                                        : L[3 * map[i] + (size_t)c];
    free(back);
    *avg = acc;
    return BN_OK;
}

/* Per patch and channel the error relative to s_c = max(|L_ref|, the scene's area-weighted mean
 * radiance in that channel): a scale that cannot vanish, so patches that see no light (under a
 * block, L_ref ~ 0) count at the scene's typical brightness instead of blowing up. Then the
 * largest, and the area-weighted L1 and L2 (RMS) norms. */
static void bn__patch_errors(const bn__study_ref *ref, const double *L, const size_t *map, const double *avg,
                             bn_study_row *row)
{
    size_t nr;
    const bn_patch *pr = bn_scene_patches(ref->scene, &nr);
    double sum_a = 0, sum_e1 = 0, sum_e2 = 0;
    nr = ref->n;
    row->err_inf = row->err_max_rel = 0;
    for (size_t i = 0; i < nr; i++) {
        size_t j = map ? map[i] : i;
        for (int c = 0; c < 3; c++) {
            double v = avg ? avg[4 * i + (size_t)c] : L[3 * j + (size_t)c];
            double lr = ref->L[3 * i + (size_t)c], d = fabs(v - lr);
            double rel = d / fmax(fabs(lr), ref->floor[c]);
            row->err_inf = fmax(row->err_inf, d);
            row->err_max_rel = fmax(row->err_max_rel, rel);
            sum_e1 += pr[i].area * rel;
            sum_e2 += pr[i].area * rel * rel;
        }
        sum_a += 3 * pr[i].area;
    }
    row->err_inf_rel = ref->norm_L > 0 ? row->err_inf / ref->norm_L : row->err_inf;
    row->err_l1_rel = sum_a > 0 ? sum_e1 / sum_a : 0;
    row->err_rms_rel = sum_a > 0 ? sqrt(sum_e2 / sum_a) : 0;
}

/* Per surface (material): the largest relative error of its mean over the channels, and their
 * largest and mean over the surfaces used. */
static void bn__surface_errors(const bn__study_ref *ref, const double *means, bn_study_row *row)
{
    size_t counted = 0;
    row->err_surface_max = 0;
    row->err_surface_mean = 0;
    for (size_t m = 0; m < ref->nsurf; m++) {
        double e = 0, top = 0;
        for (int c = 0; c < 3; c++)
            top = fmax(top, ref->surf_mean[3 * m + (size_t)c]);
        if (top <= 0) {   /* a material no patch uses */
            if (row->err_surface)
                row->err_surface[m] = NAN;
            continue;
        }
        for (int c = 0; c < 3; c++) {
            double r = ref->surf_mean[3 * m + (size_t)c];
            e = fmax(e, fabs(means[3 * m + (size_t)c] - r) / fmax(r, 1e-6 * top));
        }
        if (row->err_surface)
            row->err_surface[m] = e;
        row->err_surface_max = fmax(row->err_surface_max, e);
        row->err_surface_mean += e;
        counted++;
    }
    row->err_surface_mean = counted ? row->err_surface_mean / (double)counted : 0;
}

bn_status bn__study_compare(const bn__study_ref *ref, const bn_scene *s, const double *L, bn_study_row *row,
                            bn_error *err)
{
    size_t ns, nr = ref->n;
    size_t *map = NULL;
    double *E = NULL, *means = NULL, *avg = NULL, power[3];
    int same = bn__same_mesh(ref->scene, s);
    bn_status st = BN_OK;
    bn_scene_patches(s, &ns);
    row->ground = same ? 0 : 1;
    E = bn__malloc_array(3 * ns + 1, sizeof(double));
    means = bn__malloc_array(3 * ref->nsurf + 1, sizeof(double));
    if (!same)
        map = bn__malloc_array(nr + 1, sizeof(size_t));
    if (!E || !means || (!same && !map))
        st = bn_error_set(err, BN_ENOMEM, "study: out of memory comparing %zu patches", ns);
    if (st == BN_OK && !same)
        st = bn__lookup(ref->scene, s, map, err);
    if (st == BN_OK && !same && ns > nr) {
        st = bn__area_means(ref, s, L, map, &avg, err);
        row->ground = 2;
    }
    if (st == BN_OK) {
        bn__patch_errors(ref, L, same ? NULL : map, avg, row);
        bn_scene_patch_emission(s, E);
        bn__study_reflected_power(s, L, E, power);
        row->err_energy_rel = 0;
        for (int c = 0; c < 3; c++)
            if (ref->power[c] > 0)
                row->err_energy_rel = fmax(row->err_energy_rel, fabs(power[c] - ref->power[c]) / ref->power[c]);
        bn__study_surface_means(s, L, ref->nsurf, means);
        bn__surface_errors(ref, means, row);
    }
    free(E);
    free(means);
    free(map);
    free(avg);
    return st;
}
