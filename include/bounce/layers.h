/* bounce: how the terms of the series are named and stacked, the one convention every output
 * follows. Bounce k is the term K^k E: E (k = 0) is emission, KE (k = 1) direct light, K2E the
 * first indirect bounce, and so on. A result that keeps E .. K^b E separately has b + 3 layers:
 *   layer k <= b: K^k E;   layer b + 1: rest = L - (E + KE + ... + K^b E);   layer b + 2: L. */
#ifndef BOUNCE_LAYERS_H
#define BOUNCE_LAYERS_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* b + 3: the terms E .. K^b E, rest and L. */
int bn_layer_count(int bounces);
/* The name of layer `layer` of a result keeping bounces b: "E", "KE", "K2E", ..., "rest", "L".
 * Writes into buf (16 bytes suffice) and returns it. */
const char *bn_layer_name(int layer, int bounces, char *buf, size_t size);
/* The name of the term K^k E: "E", "KE", "K2E", ... */
const char *bn_term_name(int k, char *buf, size_t size);
/* rest[j] = L[j] - sum_{k<nterms} terms[k][j], for j < m (m = 3N values). */
void bn_layers_rest(const double *const *terms, int nterms, const double *L, size_t m, double *rest);
/* Stacks the layers of a result keeping bounces b into out (bn_layer_count(b) blocks of N*3):
 * the terms, then rest, then L. */
void bn_layers_stack(const double *const *terms, const double *L, size_t n, int bounces, double *out);

#ifdef __cplusplus
}
#endif
#endif
