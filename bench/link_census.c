/* Where the hierarchy's links are: a census of the frozen link set of a scene solved with the defaults
 * (the hierarchical transport), by the receiver's object, by pair of objects, and by kind (a node or a
 * patch at each end; how many of each kind join nodes whose bounding spheres overlap: the pairs that
 * refinement splits whatever their light). Objects are the scene's own (bn_scene_object_name: a file's
 * groups, or material prefixes such as couch_). Not a test: a tool for finding what a scene's links cost.
 *
 *   link_census SCENE [--unit m|cm|mm] [--passes N] [--eps E]
 *
 * prints markdown tables on stdout (bounce's log on stderr). --passes 1 shows the first pass alone (the
 * links kept are those with F > 0; refinement's own count, zeros included, is in the log). */
#include "bounce/pipeline.h"
#include "bounce/scene.h"
#include "bounce/transport.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct census {
    size_t nobj;            /* objects; index nobj: a node spanning several */
    double *lo, *hi;        /* per node: bounding box of its patches' corners */
    int *obj;               /* per node: its object, or -1 when it spans several */
    size_t kind[4], overlap[4];   /* [2 * receiver is a patch + source is a patch] */
    size_t *by_obj, *pair;  /* links per receiver object; per (receiver, source) object pair */
    double *area;           /* patches' area per object */
} census;

static void *bn__xcalloc(size_t n, size_t size)
{
    void *p = calloc(n ? n : 1, size);
    if (!p) {
        fprintf(stderr, "link_census: out of memory (%zu x %zu bytes)\n", n, size);
        exit(1);
    }
    return p;
}

/* Each node's box and object, children before parents (a node's children have larger indices). */
static void census_nodes(census *c, const bn_transport_links *lk, const bn_scene *sc)
{
    const bn_patch *pa = bn_scene_patches(sc, NULL);
    const bn_face *fa = bn_scene_faces(sc, NULL);
    const double *pv = bn_scene_patch_vertices(sc, NULL);
    for (size_t v = lk->nnodes; v-- > 0;) {
        double *lo = c->lo + 3 * v, *hi = c->hi + 3 * v;
        if (lk->child[v] == BN_LINK_NONE) {
            const bn_patch *q = &pa[lk->leaf_patch[v]];
            for (int k = 0; k < 3; k++) {
                lo[k] = INFINITY;
                hi[k] = -INFINITY;
                for (unsigned j = 0; j < q->ncorners; j++) {
                    lo[k] = fmin(lo[k], pv[3 * q->corner[j] + k]);
                    hi[k] = fmax(hi[k], pv[3 * q->corner[j] + k]);
                }
            }
            c->obj[v] = (int)fa[q->face].object;
            c->area[c->obj[v]] += q->area;
            continue;
        }
        uint32_t a = lk->child[v];
        for (int k = 0; k < 3; k++) {
            lo[k] = fmin(c->lo[3 * a + k], c->lo[3 * (a + 1) + k]);
            hi[k] = fmax(c->hi[3 * a + k], c->hi[3 * (a + 1) + k]);
        }
        c->obj[v] = c->obj[a] == c->obj[a + 1] ? c->obj[a] : -1;
    }
}

/* Node v's bounding sphere (the box's): centre x, radius returned. */
static double census_sphere(const census *c, size_t v, double x[3])
{
    double r2 = 0;
    for (int k = 0; k < 3; k++) {
        double e = 0.5 * (c->hi[3 * v + k] - c->lo[3 * v + k]);
        x[k] = 0.5 * (c->hi[3 * v + k] + c->lo[3 * v + k]);
        r2 += e * e;
    }
    return sqrt(r2);
}

static void census_links(census *c, const bn_transport_links *lk)
{
    for (size_t r = 0; r < lk->nnodes; r++) {
        double xr[3], xs[3], rr = census_sphere(c, r, xr);
        size_t a = c->obj[r] < 0 ? c->nobj : (size_t)c->obj[r];
        for (size_t l = lk->start[r]; l < lk->start[r + 1]; l++) {
            uint32_t s = lk->src[l];
            double rs = census_sphere(c, s, xs), d2 = 0;
            for (int k = 0; k < 3; k++)
                d2 += (xr[k] - xs[k]) * (xr[k] - xs[k]);
            int kind = 2 * (lk->child[r] == BN_LINK_NONE) + (lk->child[s] == BN_LINK_NONE);
            size_t b = c->obj[s] < 0 ? c->nobj : (size_t)c->obj[s];
            c->kind[kind]++;
            c->overlap[kind] += d2 <= (rr + rs) * (rr + rs);
            c->by_obj[a]++;
            c->pair[a * (c->nobj + 1) + b]++;
        }
    }
}

static const char *census_name(const bn_scene *sc, const census *c, size_t k)
{
    return k < c->nobj ? bn_scene_object_name(sc, k) : "(several)";
}

static void census_print(const census *c, const bn_scene *sc, size_t nlinks)
{
    static const char *kinds[4] = {"node <- node", "node <- patch", "patch <- node", "patch <- patch"};
    double all = nlinks ? (double)nlinks : 1;
    printf("| kind (receiver <- source) | links | share | spheres overlap |\n|---|---:|---:|---:|\n");
    for (int k = 0; k < 4; k++)
        printf("| %s | %zu | %.1f%% | %zu |\n", kinds[k], c->kind[k], 100 * c->kind[k] / all, c->overlap[k]);
    printf("\n| receiver object | links | share | area | links per unit area |\n|---|---:|---:|---:|---:|\n");
    for (size_t a = 0; a <= c->nobj; a++)
        if (c->by_obj[a])
            printf("| %s | %zu | %.1f%% | %.4g | %.4g |\n", census_name(sc, c, a), c->by_obj[a],
                   100 * c->by_obj[a] / all, a < c->nobj ? c->area[a] : NAN,
                   a < c->nobj && c->area[a] > 0 ? c->by_obj[a] / c->area[a] : NAN);
    printf("\n| receiver <- source | links | share |\n|---|---|---:|\n");
    size_t m = (c->nobj + 1) * (c->nobj + 1);
    for (int t = 0; t < 12; t++) {
        size_t best = 0, bi = 0;
        for (size_t i = 0; i < m; i++)
            if (c->pair[i] > best) {
                best = c->pair[i];
                bi = i;
            }
        if (!best)
            break;
        printf("| %s <- %s | %zu | %.1f%% |\n", census_name(sc, c, bi / (c->nobj + 1)),
               census_name(sc, c, bi % (c->nobj + 1)), best, 100 * best / all);
        c->pair[bi] = 0;
    }
}

static int usage(const char *why)
{
    fprintf(stderr, "link_census: %s\nusage: link_census SCENE [--unit m|cm|mm] [--passes N] [--eps E]\n", why);
    return 2;
}

/* Options into o; 0, or the exit code of a usage error. */
static int census_args(int argc, char **argv, bn_pipeline_opts *o)
{
    for (int i = 2; i < argc; i++) {
        char *end = NULL;
        if (i + 1 >= argc)
            return usage("an option without its value");
        if (!strcmp(argv[i], "--unit")) {
            if (bn_unit_parse(argv[++i], &o->load.unit))
                return usage("--unit takes m, cm or mm");
        } else if (!strcmp(argv[i], "--passes")) {
            long n = strtol(argv[++i], &end, 10);
            if (*end || n < 1 || n > 64)
                return usage("--passes takes a whole number from 1 to 64");
            o->hier.max_passes = (int)n;
        } else if (!strcmp(argv[i], "--eps")) {
            o->hier.eps = strtod(argv[++i], &end);
            if (*end || !(o->hier.eps > 0))
                return usage("--eps takes a positive number");
        } else
            return usage("unknown option");
    }
    return 0;
}

int main(int argc, char **argv)
{
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_transport_links lk;
    bn_error err;
    if (argc < 2)
        return usage("no scene");
    bn_pipeline_opts_default(&o);
    o.mesh_auto = 1;
    o.method_auto = 1;
    o.transport = "hierarchical";
    o.solve.bounces = 1;
    int rc = census_args(argc, argv, &o);
    if (rc)
        return rc;
    if (bn_pipeline_run(argv[1], &o, &p, &err) != BN_OK || bn_transport_links_get(p.k, &lk, &err) != BN_OK) {
        fprintf(stderr, "link_census: %s\n", err.msg);
        return 1;
    }
    census c = {.nobj = bn_scene_object_count(p.scene)};
    c.lo = bn__xcalloc(3 * lk.nnodes, sizeof(double));
    c.hi = bn__xcalloc(3 * lk.nnodes, sizeof(double));
    c.obj = bn__xcalloc(lk.nnodes, sizeof(int));
    c.by_obj = bn__xcalloc(c.nobj + 1, sizeof(size_t));
    c.pair = bn__xcalloc((c.nobj + 1) * (c.nobj + 1), sizeof(size_t));
    c.area = bn__xcalloc(c.nobj + 1, sizeof(double));
    census_nodes(&c, &lk, p.scene);
    census_links(&c, &lk);
    printf("%s: %zu patches, %zu nodes, %zu links kept (F > 0)\n\n", argv[1], lk.npatch, lk.nnodes, lk.nlinks);
    census_print(&c, p.scene, lk.nlinks);
    free(c.lo), free(c.hi), free(c.obj), free(c.by_obj), free(c.pair), free(c.area);
    bn_transport_links_free(&lk);
    bn_pipeline_free(&p);
    return 0;
}
