/* One form factor at a time, computed exactly as the dense assembly computes it (the same
 * quadrature, the same seeded shadow rays), for operators that choose their own pairs: the
 * hierarchy's leaf links. Not installed. */
#ifndef BN_FF_PAIR_H
#define BN_FF_PAIR_H

#include "bounce/formfactor.h"

#include <math.h>

typedef struct bn__ff_pairs bn__ff_pairs;     /* geometry, rays and options; read-only once made */
typedef struct bn__ff_worker bn__ff_worker;   /* one thread's scratch */

/* o: method analytic or montecarlo (hemisphere has no pairs: BN_EUSAGE). */
bn_status bn__ff_pairs_create(const bn_scene *scene, const bn_rt *rt, const bn_formfactor_opts *o,
                              bn__ff_pairs **out, bn_error *err);
void bn__ff_pairs_destroy(bn__ff_pairs *p);
bn__ff_worker *bn__ff_worker_create(const bn__ff_pairs *p);   /* NULL: out of memory */
void bn__ff_worker_destroy(bn__ff_worker *w);
/* A_i F_ij (= A_j F_ji) of patches i and j with visibility; 0 when they cannot see each other.
 * cull 1: skip the rays when no face can lie between them (as the dense assembly does; costs a
 * pass over the faces per new row); 0: always cast them (an unblocked pair gets exactly the same
 * value). */
double bn__ff_pair(const bn__ff_pairs *p, bn__ff_worker *w, size_t i, size_t j, int cull);
/* A bound of the standard error of F estimated as F_unoccluded x a visible fraction from n rays:
 * F_unoccluded / (2 sqrt n) (the fraction's variance v (1 - v) / n is at most 1 / 4n). Where it is
 * below a caller's tolerance, a partly visible estimate needs no more rays. */
static inline double bn__ff_vis_noise(double F, double n) { return F * 0.5 / sqrt(n); }

/* The largest sample count bn__ff_pair_quick uses. */
#define BN__FF_QUICK_MAX 256
/* F_ij (receiver i): the unoccluded form factor by the dense assembly's quadrature (to rtol) times the
 * visible fraction from S shadow rays between point pairs (4S when the first S find partial
 * visibility and their standard error's bound, F_unoccluded / (2 sqrt S), exceeds ftol; ftol 0:
 * whenever partial): the dense value but for fewer, freshly seeded rays. *sigma: the visibility
 * estimate's standard error times the unoccluded F; *first_only: 1 when the first S found partial
 * visibility and ftol spared the second look (a caller that later wants it calls again). */
double bn__ff_pair_quick(const bn__ff_pairs *p, bn__ff_worker *w, size_t i, size_t j, int S, double rtol,
                         double ftol, double *sigma, int *first_only);
size_t bn__ff_worker_rays(const bn__ff_worker *w);   /* rays cast so far */

#endif
