/* The command line's further options for the flat API's callers (Python's keywords), by the names of
 * the library's struct fields: `name=value` lines (bn_flat_opts.more for the scene, F and the solve;
 * bn_flat_set for the images and the bake). One table: its names are the vocabularies
 * "scene_options", "solve_options", "image_options" and "bake_options" (bn_flat_names), its ranges
 * the command line's. */
#include "pipeline/flat_internal.h"

#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

enum { BN__M_SCENE, BN__M_SOLVE, BN__M_IMAGE, BN__M_BAKE };   /* which call reads the option */
enum { BN__M_DBL, BN__M_INT, BN__M_SIZE, BN__M_FLAG, BN__M_NOT, BN__M_STR, BN__M_ORIENT, BN__M_EV, BN__M_VEC3 };

typedef struct bn__more_opt {
    const char *name;
    unsigned char stage, kind;
    size_t off;        /* into bn_pipeline_opts (scene, solve) or bn__flat_call (image, bake) */
    double lo, hi;
} bn__more_opt;

#define P_(m) offsetof(bn_pipeline_opts, m)
#define C_(m) offsetof(bn__flat_call, m)
static const bn__more_opt bn__more[] = {
    {"no_subdivide", BN__M_SCENE, BN__M_FLAG, P_(mesh.no_subdivide), 0, 1},
    {"no_contacts", BN__M_SCENE, BN__M_FLAG, P_(mesh.no_contacts), 0, 1},
    {"self_contacts", BN__M_SCENE, BN__M_FLAG, P_(mesh.self_contacts), 0, 1},
    {"contact_gap", BN__M_SCENE, BN__M_DBL, P_(mesh.contact_gap), 0, 1e300},
    {"planar_tol", BN__M_SCENE, BN__M_DBL, P_(load.planar_tol), 1e-300, 1},
    {"orient", BN__M_SCENE, BN__M_ORIENT, P_(load.orient), 0, 0},
    {"two_sided", BN__M_SCENE, BN__M_STR, P_(load.two_sided), 0, 0},
    {"no_clusters", BN__M_SCENE, BN__M_NOT, P_(hier.clusters), 0, 1},
    {"no_flat_clusters", BN__M_SCENE, BN__M_NOT, P_(hier.flat_clusters), 0, 1},
    {"no_volume_links", BN__M_SCENE, BN__M_NOT, P_(hier.volume_links), 0, 1},
    {"normalize_rows", BN__M_SCENE, BN__M_FLAG, P_(hier.normalize_rows), 0, 1},
    {"link_samples", BN__M_SCENE, BN__M_INT, P_(hier.samples), 1, 1 << 16},
    {"min_area", BN__M_SCENE, BN__M_DBL, P_(hier.min_area), -1, 1e300},
    {"samples", BN__M_SCENE, BN__M_INT, P_(ff.samples), 1, 1 << 24},
    {"sparse_threshold", BN__M_SCENE, BN__M_DBL, P_(ff.sparse_threshold), 0, 0.999},
    {"max_memory", BN__M_SCENE, BN__M_SIZE, P_(ff.max_memory), 1, 1e18},
    {"ff_tolerance", BN__M_SCENE, BN__M_DBL, P_(ff.tolerance), 1e-12, 0.1},
    {"ff_quadrature_only", BN__M_SCENE, BN__M_FLAG, P_(ff.quadrature_only), 0, 1},
    {"singular_threshold", BN__M_SOLVE, BN__M_DBL, P_(solve.singular_threshold), 0, 0.5},
    {"symmetric", BN__M_SOLVE, BN__M_FLAG, P_(solve.symmetric), 0, 1},
    {"light_samples", BN__M_IMAGE, BN__M_INT, C_(bo.light_samples), 1, 65536},
    {"gather_samples", BN__M_IMAGE, BN__M_INT, C_(bo.gather_samples), 1, 1 << 20},
    {"gather_filter", BN__M_IMAGE, BN__M_INT, C_(bo.gather_filter), 0, 64},
    {"hit_emitters", BN__M_IMAGE, BN__M_INT, C_(bo.hit_emitters), 0, 1 << 20},
    {"tree_emitters", BN__M_IMAGE, BN__M_INT, C_(bo.tree_emitters), 0, 1 << 30},
    {"tile", BN__M_IMAGE, BN__M_INT, C_(bo.tile), 16, 4096},
    {"exposure", BN__M_IMAGE, BN__M_EV, C_(bo.ev), -64, 64},
    {"crease", BN__M_IMAGE, BN__M_DBL, C_(bo.crease), 0, 180},
    {"up", BN__M_IMAGE, BN__M_VEC3, C_(up), -1e300, 1e300},
    {"gather_rays", BN__M_BAKE, BN__M_INT, C_(gather_rays), 1, 1 << 20},
    {"bake_tol", BN__M_BAKE, BN__M_DBL, C_(bake_tol), 1e-4, 10},
    {"flat", BN__M_BAKE, BN__M_FLAG, C_(flat), 0, 1},
    {"no_colour_sets", BN__M_BAKE, BN__M_FLAG, C_(no_colour_sets), 0, 1},
};
#undef P_
#undef C_
#define BN__NMORE (sizeof bn__more / sizeof *bn__more)

static char bn__more_joined[4][512];

static void bn__more_join(void)
{
    size_t k[4] = {0, 0, 0, 0};
    for (size_t i = 0; i < BN__NMORE; i++) {
        int s = bn__more[i].stage;
        k[s] += (size_t)snprintf(bn__more_joined[s] + k[s], sizeof bn__more_joined[s] - k[s], "%s%s", k[s] ? "|" : "",
                                 bn__more[i].name);
    }
}

/* The names of a stage's options, "|"-separated (joined once, thread-safe). */
static const char *bn__more_names(int stage)
{
    static pthread_once_t once = PTHREAD_ONCE_INIT;
    pthread_once(&once, bn__more_join);
    return bn__more_joined[stage];
}
const char *bn__flat_scene_options(void) { return bn__more_names(BN__M_SCENE); }
const char *bn__flat_solve_options(void) { return bn__more_names(BN__M_SOLVE); }
const char *bn__flat_image_options(void) { return bn__more_names(BN__M_IMAGE); }
const char *bn__flat_bake_options(void) { return bn__more_names(BN__M_BAKE); }

void bn__flat_call_default(bn__flat_call *c)
{
    memset(c, 0, sizeof *c);
    bn_bounces_opts_default(&c->bo);
    c->gather_rays = BN_BAKE_GATHER_RAYS;
    c->bake_tol = BN_BAKE_REFINE_TOL;
}

/* text into msg (this file calls nothing of flat.c's: flat.c calls it) */
static bn_status bn__more_fail(bn_status st, const char *text, char *msg, size_t msglen)
{
    if (msg && msglen)
        snprintf(msg, msglen, "%s", text);
    return st;
}

/* A number of the option's kind within its range, or -1 with the reason in msg. */
static int bn__more_number(const bn__more_opt *o, const char *v, double *out, char *msg, size_t msglen)
{
    char *end;
    double x = strtod(v, &end);
    int whole = o->kind == BN__M_INT || o->kind == BN__M_SIZE || o->kind == BN__M_FLAG || o->kind == BN__M_NOT;
    if (end == v || *end || !isfinite(x))
        snprintf(msg, msglen, "`%s`: '%s' is not a number", o->name, v);
    else if (whole && x != floor(x))
        snprintf(msg, msglen, "`%s`: %s is not a whole number", o->name, v);
    else if (x < o->lo || x > o->hi)
        snprintf(msg, msglen, "`%s`: %s is outside [%.10g, %.10g]", o->name, v, o->lo, o->hi);
    else {
        *out = x;
        return 0;
    }
    return -1;
}

/* "x,y,z" into three finite numbers. */
static int bn__more_vec3(const bn__more_opt *o, const char *v, double out[3], char *msg, size_t msglen)
{
    char *end;
    const char *p = v;
    for (int k = 0; k < 3; k++) {
        out[k] = strtod(p, &end);
        if (end == p || !isfinite(out[k]) || *end != (k < 2 ? ',' : '\0')) {
            snprintf(msg, msglen, "`%s`: '%s' is not three numbers x,y,z", o->name, v);
            return -1;
        }
        p = end + 1;
    }
    return 0;
}

/* One option's value into its field at base (strings copied into str, size nstr). */
static int bn__more_store(const bn__more_opt *o, char *base, const char *v, char *str, size_t nstr, char *msg,
                          size_t msglen)
{
    double x = 0;
    void *dst = base + o->off;
    if (o->kind == BN__M_STR) {
        if (strlen(v) >= nstr)
            return snprintf(msg, msglen, "`%s`: '%.40s...' is too long", o->name, v), -1;
        memcpy(str, v, strlen(v) + 1);
        *(const char **)dst = str;
        return 0;
    }
    if (o->kind == BN__M_ORIENT) {
        int w = !strcmp(v, "winding");
        if (!w && strcmp(v, "normals"))
            return snprintf(msg, msglen, "`%s`: '%s' is not one of normals|winding", o->name, v), -1;
        *(bn_orient *)dst = w ? BN_ORIENT_WINDING : BN_ORIENT_NORMALS;
        return 0;
    }
    if (o->kind == BN__M_VEC3) {
        bn__flat_call *c = (bn__flat_call *)base;
        return (c->has_up = bn__more_vec3(o, v, (double *)dst, msg, msglen) == 0) ? 0 : -1;
    }
    if (bn__more_number(o, v, &x, msg, msglen) != 0)
        return -1;
    switch (o->kind) {
    case BN__M_DBL: *(double *)dst = x; break;
    case BN__M_INT: *(int *)dst = (int)x; break;
    case BN__M_SIZE: *(size_t *)dst = (size_t)x; break;
    case BN__M_FLAG: *(int *)dst = x != 0; break;
    case BN__M_NOT: *(int *)dst = x == 0; break;
    case BN__M_EV: ((bn__flat_call *)base)->bo.ev = x, ((bn__flat_call *)base)->bo.auto_exposure = 0; break;
    default: return snprintf(msg, msglen, "`%s`: no such kind of option", o->name), -1;
    }
    return 0;
}

static const char *const bn__more_where[] = {"the scene and F (give it where the scene is loaded or solved from its file)",
                                             "the solve", "the images (images, render)", "the bake"};

/* Each `name=value` line of text into po (stages scene and solve) or c (image and bake): the stages from
 * lo to hi are taken, others refused by name with where they belong. */
static bn_status bn__more_parse(const char *text, int lo, int hi, bn_pipeline_opts *po, bn__flat_call *c, char *str,
                                size_t nstr, char *msg, size_t msglen)
{
    char line[640], t[768] = "";
    for (const char *p = text; p && *p;) {
        const char *e = strchr(p, '\n');
        size_t n = e ? (size_t)(e - p) : strlen(p);
        if (n >= sizeof line)
            return bn__more_fail(BN_EUSAGE, "an option line is longer than 639 characters", msg, msglen);
        snprintf(line, sizeof line, "%.*s", (int)n, p);
        p = e ? e + 1 : NULL;
        char *eq = strchr(line, '=');
        if (!line[0])
            continue;
        if (eq)
            *eq = '\0';
        size_t i = 0;
        while (i < BN__NMORE && strcmp(bn__more[i].name, line) != 0)
            i++;
        if (i == BN__NMORE || !eq)
            snprintf(t, sizeof t, "no option `%s`=VALUE here (options: %s, %s)", line, bn__more_names(lo), bn__more_names(hi));
        else if (bn__more[i].stage < lo || bn__more[i].stage > hi)
            snprintf(t, sizeof t, "`%s` is an option of %s", line, bn__more_where[bn__more[i].stage]);
        else if (bn__more_store(&bn__more[i], bn__more[i].stage <= BN__M_SOLVE ? (char *)po : (char *)c, eq + 1, str,
                                nstr, t, sizeof t) == 0)
            continue;
        return bn__more_fail(BN_EUSAGE, t, msg, msglen);
    }
    return BN_OK;
}

bn_status bn__flat_more_pipeline(const char *text, int solve_only, bn_flat *f, bn_pipeline_opts *po, char *msg,
                                 size_t msglen)
{
    return bn__more_parse(text, solve_only ? BN__M_SOLVE : BN__M_SCENE, BN__M_SOLVE, po, NULL, f->two_sided,
                          sizeof f->two_sided, msg, msglen);
}

bn_status bn_flat_set(bn_flat *f, const char *more, char *msg, size_t msglen)
{
    if (msg && msglen)
        msg[0] = '\0';
    if (!f)
        return bn__more_fail(BN_EUSAGE, "set: no handle", msg, msglen);
    bn__flat_call_default(&f->call);
    bn_status st = bn__more_parse(more, BN__M_IMAGE, BN__M_BAKE, NULL, &f->call, NULL, 0, msg, msglen);
    if (st != BN_OK)
        bn__flat_call_default(&f->call);
    return st;
}
