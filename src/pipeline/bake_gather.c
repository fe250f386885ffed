/* The gathered bake (include/bounce/pipeline.h): each bake vertex's values by the final gather at the
 * vertex (bn_gather_points: E, KE, ..., rest, L), the element mesh refined first where L changes
 * (bn_bake_refine: crack-free, up to a vertex budget). `bounce bake` and the flat API's bake share it. */
#include "bounce/pipeline.h"
#include "bounce/bake.h"
#include "bounce/gather.h"
#include "base/internal.h"

#include <string.h>

void bn_bake_gather_opts_default(bn_bake_gather_opts *o)
{
    memset(o, 0, sizeof *o);
    o->gather_rays = BN_BAKE_GATHER_RAYS;
    o->max_vertices = BN_BAKE_DEFAULT_VERTICES;
    o->tol = BN_BAKE_REFINE_TOL;
    o->seed = 1;
}

typedef struct bn__bake_eval_ctx {
    const bn_bake_gather_opts *o;
    const bn_pipeline *p;
    bn_gather_stats sum;      /* over every call: rays and seconds added, the lights' counts kept */
    size_t points;
} bn__bake_eval_ctx;

static bn_status bn__bake_eval(void *user, const double *x, const size_t *patch, size_t n, size_t first, double *out,
                               bn_error *err)
{
    bn__bake_eval_ctx *e = user;
    bn_gather_opts go;
    bn_gather_stats gs;
    bn_status st;
    bn_gather_opts_default(&go);
    go.hemi_samples = e->o->gather_rays;
    go.light_samples = BN_BAKE_GATHER_LIGHT;
    go.seed = first ? e->o->seed ^ bn__hash64((uint64_t)first) : e->o->seed;
    go.threads = e->o->threads;
    go.quiet = e->o->quiet || first > 0;   /* a bar for the first batch; the rounds say their own line */
    st = bn_gather_points(e->p->rt, (const double *const *)e->p->res.terms, e->p->res.nterms - 1, e->p->rest, x,
                          patch, n, &go, out, &gs, err);
    e->points += n;
    e->sum.gather_rays += gs.gather_rays;
    e->sum.shadow_rays += gs.shadow_rays;
    e->sum.seconds += gs.seconds;
    e->sum.emitters = gs.emitters;
    e->sum.lights = gs.lights;
    return st;
}

/* The gather's line in the bake's log: its rays (the near hits' gathers included) and time. */
static void bn__bake_gather_log(const bn__bake_eval_ctx *e)
{
    bn_logf(e->o->log, BN_LOG_INFO, "bake: the gather at %zu points (vertices, probed midpoints): %.3g hemisphere "
            "rays (%.0f a point, the near hits' own gathers included; %d asked, rounded up to a square), %.3g shadow "
            "rays (%zu emitting face%s as %zu light%s), %.1f s",
            e->points, e->sum.gather_rays, e->points ? e->sum.gather_rays / (double)e->points : 0, e->o->gather_rays,
            e->sum.shadow_rays, e->sum.emitters, e->sum.emitters == 1 ? "" : "s", e->sum.lights,
            e->sum.lights == 1 ? "" : "s", e->sum.seconds);
}

bn_status bn_pipeline_bake_gather(const bn_pipeline *p, bn_bake *bake, const bn_bake_gather_opts *o,
                                  bn_bake_layer *layers, size_t nl, double **vbuf, bn_error *err)
{
    int n = p->res.nterms - 1;
    bn__bake_eval_ctx ctx;
    bn_bake_refine_opts ro;
    memset(&ctx, 0, sizeof ctx);
    ctx.o = o;
    ctx.p = p;
    if (!p->rt || n < 1)
        return bn_error_set(err, BN_EUSAGE,
                            "a gathered bake needs the ray scene and a solve keeping KE (bounces >= 1)");
    bn_bake_refine_opts_default(&ro);
    ro.max_vertices = o->max_vertices;
    ro.tol = o->tol;
    ro.nlayers = (size_t)n + 3;
    ro.key = (size_t)n + 2;
    ro.eval = bn__bake_eval;
    ro.user = &ctx;
    ro.log = o->log;
    bn_status st = bn_bake_refine(bake, &ro, vbuf, err);
    if (st == BN_OK)
        bn__bake_gather_log(&ctx);
    size_t nv = bn_bake_vertex_count(bake);
    for (size_t l = 0; st == BN_OK && l < nl; l++) {   /* L, then E .. K^n E, rest */
        size_t k = l == 0 ? (size_t)n + 2 : l - 1 <= (size_t)n ? l - 1 : (size_t)n + 1;
        layers[l].vertex_values = *vbuf + k * nv * 3;
    }
    return st;
}
