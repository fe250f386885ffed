/* A reporting partition (include/bounce/trace.h): regions of whole input polygons, one material
 * each, area-balanced by median splits (polygons above an even share taken first, each a region of
 * its own), for a cross-check coarse enough for the tracer. */
#include "bounce/trace.h"
#include "base/internal.h"
#include "base/vec.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct bn__pkey {
    double k;
    uint32_t f;
} bn__pkey;

static int bn__pkey_cmp(const void *a, const void *b)
{
    const bn__pkey *x = a, *y = b;
    if (x->k != y->k)
        return x->k < y->k ? -1 : 1;
    return x->f < y->f ? -1 : x->f > y->f;
}

typedef struct bn__split {
    const double *fc, *fa;   /* per face: centroid, area */
    uint32_t *region;        /* per face */
    bn__pkey *keys;
    size_t next;             /* next region id */
} bn__split;

/* faces[0..m) into k regions by area-median splits along the longest axis of their centroids. */
static void bn__split_faces(bn__split *S, uint32_t *faces, size_t m, size_t k)
{
    if (k > m)
        k = m;
    if (k <= 1 || m <= 1) {
        for (size_t i = 0; i < m; i++)
            S->region[faces[i]] = (uint32_t)S->next;
        S->next++;
        return;
    }
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY}, total = 0, acc = 0;
    int ax = 0;
    for (size_t i = 0; i < m; i++) {
        for (int c = 0; c < 3; c++) {
            lo[c] = fmin(lo[c], S->fc[3 * faces[i] + c]);
            hi[c] = fmax(hi[c], S->fc[3 * faces[i] + c]);
        }
        total += S->fa[faces[i]];
    }
    for (int c = 1; c < 3; c++)
        if (hi[c] - lo[c] > hi[ax] - lo[ax])
            ax = c;
    for (size_t i = 0; i < m; i++) {
        S->keys[i].k = S->fc[3 * faces[i] + ax];
        S->keys[i].f = faces[i];
    }
    qsort(S->keys, m, sizeof *S->keys, bn__pkey_cmp);
    for (size_t i = 0; i < m; i++)
        faces[i] = S->keys[i].f;
    size_t k1 = k / 2, cut = 1;
    for (size_t i = 0; i + 1 < m; i++) {   /* the first cut with k1/k of the area before it */
        acc += S->fa[faces[i]];
        cut = i + 1;
        if (acc >= total * (double)k1 / (double)k)
            break;
    }
    /* at most one region per polygon on each side; what one side cannot use goes to the other */
    if (k1 > cut)
        k1 = cut;
    if (k - k1 > m - cut)
        k1 = k - (m - cut);
    bn__split_faces(S, faces, cut, k1);
    bn__split_faces(S, faces + cut, m - cut, k - k1);
}

void bn_partition_free(bn_partition *p)
{
    if (!p)
        return;
    free(p->of_patch);
    free(p->start);
    free(p->patch);
    free(p->cum);
    free(p->area);
    free(p->material);
    free(p->centroid);
    memset(p, 0, sizeof *p);
}

/* Material m's faces (file order) into about k regions: polygons larger than an even share are
 * regions of their own (a wall), so that splits by area among the rest do not leave slivers beside
 * them; the rest split by area medians. faces: scratch of nf. */
static void bn__split_material(bn__split *S, const bn_face *f, size_t nf, unsigned m, double marea, size_t k,
                               uint32_t *faces)
{
    size_t cnt = 0, big = 0;
    double left = marea;
    for (size_t q = 0; q < nf; q++)
        if (f[q].material == m)
            faces[cnt++] = (uint32_t)q;
    for (size_t q = 0; q < cnt; q++)
        S->keys[q] = (bn__pkey){-S->fa[faces[q]], faces[q]};
    qsort(S->keys, cnt, sizeof *S->keys, bn__pkey_cmp);
    while (big < cnt && k > 1 && -S->keys[big].k >= left / (double)k) {
        S->region[S->keys[big].f] = (uint32_t)S->next++;
        left += S->keys[big].k;
        big++;
        k--;
    }
    if (big) {   /* the rest, in file order */
        size_t w = 0;
        for (size_t q = 0; q < cnt; q++) {
            int own = 0;
            for (size_t b = 0; b < big && !own; b++)
                own = S->keys[b].f == faces[q];
            if (!own)
                faces[w++] = faces[q];
        }
        cnt = w;
    }
    if (cnt)
        bn__split_faces(S, faces, cnt, k);
}

/* Regions whose polygons hold no patch are dropped (the tracer needs a patch to sample), the rest
 * renumbered in order. */
static bn_status bn__drop_empty(bn__split *S, const bn_patch *pa, size_t np, size_t nf, bn_error *err)
{
    uint32_t *id = bn__malloc_array(S->next + 1, sizeof(uint32_t));
    unsigned char *used = bn__calloc(S->next + 1, 1);
    size_t kept = 0;
    bn_status st = id && used ? BN_OK : bn_error_set(err, BN_ENOMEM, "out of memory for a partition");
    for (size_t i = 0; st == BN_OK && i < np; i++) {
        if (S->region[pa[i].face] == UINT32_MAX)   /* a patch on a face of no area: cannot happen */
            st = bn_error_set(err, BN_EINTERNAL, "partition: patch %zu lies in no region", i);
        else
            used[S->region[pa[i].face]] = 1;
    }
    if (st == BN_OK) {
        for (size_t g = 0; g < S->next; g++)
            id[g] = used[g] ? (uint32_t)kept++ : UINT32_MAX;
        for (size_t q = 0; q < nf; q++)
            if (S->region[q] != UINT32_MAX)
                S->region[q] = id[S->region[q]];
        S->next = kept;
    }
    free(id);
    free(used);
    return st;
}

/* out's arrays from each face's region: patches grouped by region, their running area shares, each
 * region's area, material and area-weighted centroid. */
static bn_status bn__partition_fill(const bn__split *S, const bn_patch *pa, size_t np, bn_partition *out,
                                    bn_error *err)
{
    size_t *fill;
    out->n = S->next;
    out->npatch = np;
    out->of_patch = bn__malloc_array(np, sizeof(uint32_t));
    out->start = bn__calloc(out->n + 1, sizeof(size_t));
    out->patch = bn__malloc_array(np, sizeof(uint32_t));
    out->cum = bn__malloc_array(np, sizeof(double));
    out->area = bn__calloc(out->n, sizeof(double));
    out->material = bn__calloc(out->n, sizeof(unsigned));
    out->centroid = bn__calloc(3 * out->n, sizeof(double));
    fill = bn__malloc_array(out->n + 1, sizeof(size_t));
    if (!out->of_patch || !out->start || !out->patch || !out->cum || !out->area || !out->material || !out->centroid ||
        !fill) {
        free(fill);
        return bn_error_set(err, BN_ENOMEM, "out of memory for a partition of %zu patches", np);
    }
    for (size_t i = 0; i < np; i++) {
        uint32_t g = S->region[pa[i].face];
        out->of_patch[i] = g;
        out->start[g + 1]++;
        out->area[g] += pa[i].area;
        out->material[g] = pa[i].material;
        for (int c = 0; c < 3; c++)
            out->centroid[3 * g + c] += pa[i].area * pa[i].centroid[c];
    }
    for (size_t g = 0; g < out->n; g++) {
        out->start[g + 1] += out->start[g];
        for (int c = 0; c < 3; c++)
            out->centroid[3 * g + c] /= out->area[g] > 0 ? out->area[g] : 1;
    }
    memcpy(fill, out->start, out->n * sizeof(size_t));
    for (size_t i = 0; i < np; i++)
        out->patch[fill[out->of_patch[i]]++] = (uint32_t)i;
    free(fill);
    for (size_t g = 0; g < out->n; g++) {
        double acc = 0;
        for (size_t k = out->start[g]; k < out->start[g + 1]; k++) {
            acc += pa[out->patch[k]].area;
            out->cum[k] = acc / out->area[g];
        }
        if (out->start[g + 1] > out->start[g])
            out->cum[out->start[g + 1] - 1] = 1;
    }
    return BN_OK;
}

bn_status bn_partition_regions(const bn_scene *s, size_t nregions, bn_partition *out, bn_error *err)
{
    size_t np, nf, nm, nv, ni;
    const bn_patch *pa = bn_scene_patches(s, &np);
    const bn_face *f = bn_scene_faces(s, &nf);
    const double *v = bn_scene_vertices(s, &nv);
    const size_t *idx = bn_scene_face_indices(s, &ni);
    bn__split S = {0};
    double *fc, *fa, *marea, total = 0;
    uint32_t *faces;
    bn_status st = BN_OK;

    bn_scene_materials(s, &nm);
    memset(out, 0, sizeof *out);
    if (nregions < 1)
        return bn_error_set(err, BN_EUSAGE, "partition: %zu regions (at least 1)", nregions);
    if (np == 0 || nf == 0)
        return bn_error_set(err, BN_EINPUT, "%s: no patches to partition", bn_scene_path(s));
    fc = bn__malloc_array(3 * nf, sizeof(double));
    fa = bn__malloc_array(nf, sizeof(double));
    S.region = bn__malloc_array(nf, sizeof(uint32_t));
    S.keys = bn__malloc_array(nf, sizeof *S.keys);
    faces = bn__malloc_array(nf, sizeof(uint32_t));
    marea = bn__calloc(nm + 1, sizeof(double));
    if (!fc || !fa || !S.region || !S.keys || !faces || !marea)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for a partition of %zu polygons", nf);
    for (size_t k = 0; st == BN_OK && k < nf; k++) {
        double c[3] = {0, 0, 0};
        for (unsigned j = 0; j < f[k].nverts; j++)
            bn_v3_add(c, v + 3 * idx[f[k].first + j], c);
        bn_v3_scale(c, 1.0 / f[k].nverts, fc + 3 * k);
        fa[k] = f[k].area;
        marea[f[k].material] += f[k].area;
        total += f[k].area;
        S.region[k] = UINT32_MAX;   /* faces of a material without area stay in no region */
    }
    S.fc = fc;
    S.fa = fa;
    for (size_t m = 0; st == BN_OK && m < nm; m++) {   /* each material's faces, in file order, then split */
        size_t k = (size_t)llround((double)nregions * marea[m] / total);
        if (marea[m] > 0)
            bn__split_material(&S, f, nf, (unsigned)m, marea[m], k < 1 ? 1 : k, faces);
    }
    if (st == BN_OK)
        st = bn__drop_empty(&S, pa, np, nf, err);
    if (st == BN_OK)
        st = bn__partition_fill(&S, pa, np, out, err);
    if (st != BN_OK)
        bn_partition_free(out);
    free(fc);
    free(fa);
    free(S.region);
    free(S.keys);
    free(faces);
    free(marea);
    return st;
}

bn_status bn_partition_objects(const bn_scene *s, double own_share, bn_partition *out, bn_error *err)
{
    size_t np, nf, nm, cnt = 0;
    const bn_patch *pa = bn_scene_patches(s, &np);
    const bn_face *f = bn_scene_faces(s, &nf);
    bn__split S = {0};
    double total = 0;
    bn_status st = BN_OK;
    bn_scene_materials(s, &nm);
    memset(out, 0, sizeof *out);
    if (!(own_share >= 0 && own_share <= 1))
        return bn_error_set(err, BN_EUSAGE, "partition: own share %g is not in [0, 1]", own_share);
    if (np == 0 || nf == 0)
        return bn_error_set(err, BN_EINPUT, "%s: no patches to partition", bn_scene_path(s));
    S.region = bn__malloc_array(nf, sizeof(uint32_t));
    S.keys = bn__malloc_array(nf, sizeof *S.keys);
    if (!S.region || !S.keys)
        st = bn_error_set(err, BN_ENOMEM, "out of memory for a partition of %zu polygons", nf);
    for (size_t k = 0; k < nf; k++)
        total += f[k].area;
    /* the key: the polygon itself (negative, unique) when large, else its object and material */
    for (size_t k = 0; st == BN_OK && k < nf; k++) {
        S.region[k] = UINT32_MAX;
        if (f[k].area > 0)
            S.keys[cnt++] = (bn__pkey){own_share > 0 && f[k].area >= own_share * total
                                           ? -1.0 - (double)k
                                           : (double)f[k].object * (double)nm + (double)f[k].material,
                                       (uint32_t)k};
    }
    if (st == BN_OK) {
        qsort(S.keys, cnt, sizeof *S.keys, bn__pkey_cmp);
        for (size_t i = 0; i < cnt; i++) {
            S.next += i == 0 || S.keys[i].k != S.keys[i - 1].k;
            S.region[S.keys[i].f] = (uint32_t)(S.next - 1);
        }
        st = bn__drop_empty(&S, pa, np, nf, err);
    }
    if (st == BN_OK)
        st = bn__partition_fill(&S, pa, np, out, err);
    if (st != BN_OK)
        bn_partition_free(out);
    free(S.region);
    free(S.keys);
    return st;
}

void bn_partition_mean(const bn_partition *p, const bn_scene *s, const double *layers, int nlayers, double *out)
{
    size_t np;
    const bn_patch *pa = bn_scene_patches(s, &np);
    memset(out, 0, (size_t)nlayers * p->n * 3 * sizeof(double));
    for (int l = 0; l < nlayers; l++)
        for (size_t i = 0; i < p->npatch && i < np; i++)
            for (int c = 0; c < 3; c++)
                out[((size_t)l * p->n + p->of_patch[i]) * 3 + c] +=
                    pa[i].area * layers[((size_t)l * p->npatch + i) * 3 + c];
    for (int l = 0; l < nlayers; l++)
        for (size_t g = 0; g < p->n; g++)
            for (int c = 0; c < 3; c++)
                out[((size_t)l * p->n + g) * 3 + c] /= p->area[g] > 0 ? p->area[g] : 1;
}
