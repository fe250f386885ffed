/* Embree 3 scene over the patches: one triangle geometry, quads split in two; primID -> patch. */
#include "bounce/rt.h"
#include "base/internal.h"
#include "base/vec.h"

#include <embree3/rtcore.h>
#include <float.h>
#include <math.h>
#include <string.h>

struct bn_rt {
    const bn_scene *scene;
    RTCDevice  device;
    RTCScene   rtscene;
    size_t    *prim_patch;   /* triangle -> patch */
    double     eps;
};

static void bn__embree_error(void *user, enum RTCError code, const char *str)
{
    bn_error *err = user;
    if (err && err->status == BN_OK)
        bn_error_set(err, code == RTC_ERROR_OUT_OF_MEMORY ? BN_ENOMEM : BN_EINTERNAL, "Embree: %s", str ? str : "error");
}

/* The device with the caller's thread count (BOUNCE_EMBREE_CONFIG adds settings, e.g. "isa=sse4.2"
 * under valgrind), and an empty scene that allows the context filter (bn__front_only). */
static bn_status bn__rt_device(bn_rt *rt, int threads, bn_error *err)
{
    char cfg[256];
    const char *extra = getenv("BOUNCE_EMBREE_CONFIG");
    snprintf(cfg, sizeof cfg, "threads=%d%s%s", threads > 0 ? threads : 0, extra ? "," : "", extra ? extra : "");
    rt->device = rtcNewDevice(cfg);
    if (!rt->device)
        return bn_error_set(err, BN_EINTERNAL, "Embree: cannot create a device (error %d)", (int)rtcGetDeviceError(NULL));
    rt->rtscene = rtcNewScene(rt->device);
    rtcSetSceneFlags(rt->rtscene, RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION);   /* bn__front_only */
    rtcSetSceneBuildQuality(rt->rtscene, RTC_BUILD_QUALITY_HIGH);
    return BN_OK;
}

/* The patches as float triangles (a quad as two) and prim_patch; *m: the largest |coordinate|. */
static bn_status bn__rt_geometry(bn_rt *rt, size_t ntri, double *m, bn_error *err)
{
    size_t np, npv, t = 0;
    const bn_patch *patches = bn_scene_patches(rt->scene, &np);
    const double *pv = bn_scene_patch_vertices(rt->scene, &npv);
    RTCGeometry geom = rtcNewGeometry(rt->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    float *vb = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), npv);
    unsigned *ib = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), ntri);
    if (!vb || !ib) {
        rtcReleaseGeometry(geom);
        return bn_error_set(err, BN_ENOMEM, "Embree: out of memory for %zu triangles", ntri);
    }
    for (size_t i = 0; i < npv; i++)
        for (int k = 0; k < 3; k++) {
            vb[3 * i + k] = (float)pv[3 * i + k];
            *m = fmax(*m, fabs(pv[3 * i + k]));
        }
    for (size_t i = 0; i < np; i++) {
        const size_t *c = patches[i].corner;
        for (unsigned tri = 0; tri + 2 < patches[i].ncorners; tri++) {   /* (0 1 2), and (0 2 3) for a quad */
            ib[3 * t + 0] = (unsigned)c[0];
            ib[3 * t + 1] = (unsigned)c[tri + 1];
            ib[3 * t + 2] = (unsigned)c[tri + 2];
            rt->prim_patch[t++] = i;
        }
    }
    rtcSetGeometryUserData(geom, rt);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(rt->rtscene, geom);
    rtcReleaseGeometry(geom);
    return BN_OK;
}

bn_status bn_rt_create(const bn_scene *scene, int threads, bn_rt **out, bn_error *err)
{
    size_t np, npv, ntri = 0;
    const bn_patch *patches = bn_scene_patches(scene, &np);
    bn_rt *rt;
    double m = 0;
    bn_error local;
    bn_status st;

    *out = NULL;
    bn_scene_patch_vertices(scene, &npv);
    if (np == 0)
        return bn_error_set(err, BN_EINPUT, "%s: the scene has no patches (mesh it first)", bn_scene_path(scene));
    if (npv > 0xffffffffu)
        return bn_error_set(err, BN_ENOMEM, "too many patch vertices for Embree's 32-bit indices (%zu)", npv);
    for (size_t i = 0; i < np; i++)
        ntri += patches[i].ncorners == 4 ? 2 : 1;
    if (!(rt = calloc(1, sizeof *rt)) || !(rt->prim_patch = bn__malloc_array(ntri, sizeof(size_t)))) {
        free(rt);
        return bn_error_set(err, BN_ENOMEM, "out of memory for %zu triangles", ntri);
    }
    rt->scene = scene;
    bn_error_clear(&local);
    if ((st = bn__rt_device(rt, threads, err)) != BN_OK) {
        bn_rt_destroy(rt);
        return st;
    }
    rtcSetDeviceErrorFunction(rt->device, bn__embree_error, &local);
    st = bn__rt_geometry(rt, ntri, &m, err);
    if (st == BN_OK)
        rtcCommitScene(rt->rtscene);
    rtcSetDeviceErrorFunction(rt->device, NULL, NULL);
    if (st == BN_OK && local.status != BN_OK) {
        st = local.status;
        if (err)
            *err = local;
    }
    if (st != BN_OK) {
        bn_rt_destroy(rt);
        return st;
    }
    /* Float coordinates of size m are exact to m * 2^-24; 2^-14 * m leaves a margin of 1024 ulps
     * for Embree's own intersection error. */
    rt->eps = ldexp(fmax(m, 1e-30), -14);
    *out = rt;
    return BN_OK;
}

void bn_rt_destroy(bn_rt *rt)
{
    if (!rt)
        return;
    if (rt->rtscene)
        rtcReleaseScene(rt->rtscene);
    if (rt->device)
        rtcReleaseDevice(rt->device);
    free(rt->prim_patch);
    free(rt);
}

double bn_rt_epsilon(const bn_rt *rt) { return rt->eps; }
const bn_scene *bn_rt_scene(const bn_rt *rt) { return rt->scene; }

static void bn__ray_init(struct RTCRay *r, const double o[3], const double d[3], double tnear, double tfar)
{
    r->org_x = (float)o[0];
    r->org_y = (float)o[1];
    r->org_z = (float)o[2];
    r->dir_x = (float)d[0];
    r->dir_y = (float)d[1];
    r->dir_z = (float)d[2];
    r->tnear = (float)tnear;
    r->tfar = tfar > FLT_MAX ? FLT_MAX : (float)tfar;
    r->time = 0;
    r->mask = 0xffffffffu;
    r->id = 0;
    r->flags = 0;
}

/* A context filter that keeps only hits on a patch's front: the second look of bn_rt_intersect. */
static void bn__front_only(const struct RTCFilterFunctionNArguments *a)
{
    const bn_rt *rt = a->geometryUserPtr;
    const bn_patch *patches = bn_scene_patches(rt->scene, NULL);
    const float *ray = (const float *)a->ray;        /* SOA: dir_x at 4N, dir_y 5N, dir_z 6N (rtcore_ray.h) */
    const unsigned *hit = (const unsigned *)a->hit;  /* primID at 5N */
    unsigned N = a->N;
    for (unsigned i = 0; i < N; i++) {
        const bn_patch *p;
        if (a->valid[i] != -1)
            continue;
        p = &patches[rt->prim_patch[hit[5 * N + i]]];
        if (p->normal[0] * ray[4 * N + i] + p->normal[1] * ray[5 * N + i] + p->normal[2] * ray[6 * N + i] >= 0)
            a->valid[i] = 0;
    }
}

/* Where a ray meets the back of a patch, another patch may lie back to back with it (a two-sided
 * surface: its two sides, or a thin panel modelled as two faces), at the same distance: Embree
 * reports either. The front one is the surface the ray sees; look for it within 4 eps. */
static void bn__prefer_front(const bn_rt *rt, const double o[3], const double d[3], bn_hit *hit)
{
    struct RTCIntersectContext ctx;
    struct RTCRayHit rh;
    double dl = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), w = 4 * rt->eps / dl;
    rtcInitIntersectContext(&ctx);
    ctx.filter = bn__front_only;
    bn__ray_init(&rh.ray, o, d, fmax(0, hit->t - w), hit->t + w);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rt->rtscene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return;
    hit->patch = rt->prim_patch[rh.hit.primID];
    hit->t = rh.ray.tfar;
    bn_v3_madd(o, hit->t, d, hit->p);
    hit->front = 1;
}

int bn_rt_intersect(const bn_rt *rt, const double o[3], const double d[3], double tnear, double tfar, bn_hit *hit)
{
    struct RTCIntersectContext ctx;
    struct RTCRayHit rh;
    size_t np;
    const bn_patch *patches;
    rtcInitIntersectContext(&ctx);
    bn__ray_init(&rh.ray, o, d, tnear, tfar);
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(rt->rtscene, &ctx, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID)
        return 0;
    patches = bn_scene_patches(rt->scene, &np);
    hit->patch = rt->prim_patch[rh.hit.primID];
    hit->t = rh.ray.tfar;
    bn_v3_madd(o, hit->t, d, hit->p);
    hit->front = bn_v3_dot(patches[hit->patch].normal, d) < 0;
    if (!hit->front)
        bn__prefer_front(rt, o, d, hit);
    return 1;
}

int bn_rt_occluded(const bn_rt *rt, const double o[3], const double d[3], double tnear, double tfar)
{
    struct RTCIntersectContext ctx;
    struct RTCRay r;
    rtcInitIntersectContext(&ctx);
    bn__ray_init(&r, o, d, tnear, tfar);
    rtcOccluded1(rt->rtscene, &ctx, &r);
    return r.tfar < 0;   /* Embree sets tfar = -inf on occlusion */
}

void bn_rt_occluded_batch(const bn_rt *rt, const float *org, const float *dir, const float *tfar, size_t n,
                          unsigned char *blocked)
{
    enum { CHUNK = 256 };
    struct RTCRay rays[CHUNK];
    struct RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
    for (size_t base = 0; base < n; base += CHUNK) {
        size_t m = n - base < CHUNK ? n - base : CHUNK;
        for (size_t i = 0; i < m; i++) {
            struct RTCRay *r = &rays[i];
            size_t j = base + i;
            r->org_x = org[3 * j];
            r->org_y = org[3 * j + 1];
            r->org_z = org[3 * j + 2];
            r->dir_x = dir[3 * j];
            r->dir_y = dir[3 * j + 1];
            r->dir_z = dir[3 * j + 2];
            r->tnear = 0;
            r->tfar = tfar[j];
            r->time = 0;
            r->mask = 0xffffffffu;
            r->id = (unsigned)i;
            r->flags = 0;
        }
        rtcOccluded1M(rt->rtscene, &ctx, rays, (unsigned)m, sizeof(struct RTCRay));
        for (size_t i = 0; i < m; i++)
            blocked[base + i] = rays[i].tfar < 0;
    }
}
