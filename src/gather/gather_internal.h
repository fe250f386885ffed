/* The final gather's state and the steps its pixels and points share (src/gather/gather.c, points.c).
 * Not installed. */
#ifndef BN_GATHER_INTERNAL_H
#define BN_GATHER_INTERNAL_H

#include "bounce/gather.h"
#include "bounce/bake.h"
#include "bounce/rt.h"
#include "base/internal.h"
#include "rt/lights.h"

/* An emitter: an emitting face, or coplanar faces of one light merged (src/gather/emitters.c): its
 * corners (counter-clockwise from the front), normal and radiance. */
#define BN__EMITTER_CORNERS 6
typedef struct bn__emitter {
    double v[3 * BN__EMITTER_CORNERS];
    size_t nv, face;         /* face: its (lowest) face */
    double n[3], Le[3];
    double area, c[3], diam;   /* area, vertex mean, largest distance between two corners */
} bn__emitter;

typedef struct bn__gather {
    const bn_rt *rt;
    const bn_scene *scene;
    const bn_patch *patch;
    const bn_material *mat;
    const double *const *terms;
    const double *rest;
    double **vv;             /* smooth: vertex values of K^1 E .. K^n E, rest (n + 1 layers) */
    const bn_bake *smooth;
    int n, gl, gh;           /* terms kept; light and gather strata per side */
    bn__emitter *em;
    size_t nem, faces;       /* emitters; the emitting faces they hold */
    uint32_t *owner;         /* per scene face: its emitter (UINT32_MAX: none), when faces were merged */
    double eps;
    int hit_direct;          /* the hits' KE from the emitters (nem <= hit_emitters, or the tree), not the patches */
    int textured;            /* some material has a reflectance texture: rho per point (bn__rho_at) */
    bn__lights *tree;        /* more than tree_emitters emitting faces: picked from this tree */
    const bn_light *pl;      /* punctual lights (bn_scene_lights): their direct light in closed form */
    size_t npl;
    double unit;             /* metres per scene unit */
} bn__gather;

/* Streams: the camera's jitter, then the light and gather samples, keyed by pixel (or point) and sample. */
#define BN__GATHER_STREAM 0x67617468ULL

/* Whether emitter e holds face f (a point on it does not light itself). */
static inline int bn__em_self(const bn__gather *G, size_t e, size_t f)
{
    return G->owner ? G->owner[f] == e : G->em[e].face == f;
}

/* G->em: the scene's emitting faces, with (merge) the coplanar pieces of one convex light as one. */
bn_status bn__gather_emitters(bn__gather *G, int merge, bn_error *err);
/* A stratified grid's side for `samples` (at least 1). */
int bn__side(int samples);
/* G for terms[0 .. n] and rest under o: emitters, the light tree, punctual lights, smooth values. */
bn_status bn__gather_init(bn__gather *G, const bn_rt *rt, const double *const *terms, int n, const double *rest,
                          const bn_gather_opts *o, bn_error *err);
void bn__gather_free(bn__gather *G);
/* The shading at a surface point h (its patch, seen from its front): E and KE (rho applied) added to
 * acc[0..5]; hv (n + 1 layers x 3) receives the hemisphere means of K^1 E .. K^n E and rest at the
 * gather's hits (rho not applied), rho the reflectance at the point. Returns the point's face. */
long bn__shade(const bn__gather *G, const bn_hit *h, bn__rng *r, double *acc, double *hv, double rho[3],
               bn_gather_stats *st);

#endif
