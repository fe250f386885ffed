/* A light tree: many emitting polygons sampled in proportion to their likely contribution at a
 * point, at a cost that grows with the logarithm of their number (Conty Estevez and Kulla 2018,
 * "Importance sampling of many lights with adaptive tree splitting"; pbrt-v4's BVHLightSampler).
 *
 * Each node bounds its emitters' extent (a box), their normals (a cone: every emitter is one-sided,
 * lighting the half-space in front of it) and their power. Seen from a point x with normal n, a
 * node's importance is power x cos(theta') x cos(theta_i') / d^2, the cosines taken at the most
 * favourable angles the bounds allow (pbrt-v4's LightBounds::Importance). It is 0 only where no
 * emitter of the node can light x (all behind x, or x behind all of them): a pick is then unbiased
 * for the 1 / pdf it returns. A descent from the root chooses each child in proportion to its
 * importance.
 *
 * Shared, like the ray caster, by the final gather (its emitting faces) and the path tracer (its
 * emitting patches): it holds geometry and emitted power only, never form factors, K or a
 * solution. Deterministic: a pure function of the polygons, the point and the uniform. */
#ifndef BOUNCE_RT_LIGHTS_H
#define BOUNCE_RT_LIGHTS_H

#include <stddef.h>
#include <stdint.h>

/* One emitter given to the tree: a convex polygon (nv <= 4 corners, xyz each), its unit front
 * normal and its power (any positive measure, e.g. area x mean emitted radiance). */
typedef struct bn__light {
    const double *v;
    size_t nv;
    double n[3];
    double power;
} bn__light;

typedef struct bn__lights bn__lights;

/* The tree over n lights (n >= 1); NULL when out of memory. behind: how far behind a light's plane
 * a point may lie and still receive its light (the gather takes points within 2 eps of a plane as
 * in front of it; the tracer, 0): one light's weight is 0 beyond it. */
bn__lights *bn__lights_build(const bn__light *l, size_t n, double behind);
void bn__lights_free(bn__lights *t);   /* NULL is a no-op */

#define BN__LIGHTS_NONE SIZE_MAX

/* Within a node of at most BN__LIGHTS_CLUSTER lights, a pick weighs each light by its own
 * importance rather than following the halves' bounds. */
#define BN__LIGHTS_CLUSTER 8

/* The light picked for the point x (normal n, or NULL for no receiving cosine) from one uniform u
 * in [0, 1), and its probability in *pdf; BN__LIGHTS_NONE when no light can reach x. far > 0: a
 * node whose bounding sphere subtends a sine below `far` at x picks among its lights by power alone
 * (cheaper, and close to their contributions' ratio for a distant cluster: to about 2 far); 0:
 * every pick follows the bounds down to BN__LIGHTS_CLUSTER lights. */
size_t bn__lights_pick(const bn__lights *t, const double x[3], const double n[3], double u, double far, double *pdf);

/* The probability that bn__lights_pick(t, x, n, ., far, .) returns light i (for multiple
 * importance sampling): 0 when it never would. */
double bn__lights_pdf(const bn__lights *t, const double x[3], const double n[3], size_t i, double far);

/* Nodes and depth, for the log. */
size_t bn__lights_nodes(const bn__lights *t);
int bn__lights_depth(const bn__lights *t);

#endif
