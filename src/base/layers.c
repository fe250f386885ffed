/* The names of the series' terms and the remainder `rest`, in one place (include/bounce/layers.h). */
#include "bounce/layers.h"

#include <stdio.h>
#include <string.h>

int bn_layer_count(int bounces) { return bounces + 3; }

const char *bn_term_name(int k, char *buf, size_t size)
{
    if (k == 0)
        snprintf(buf, size, "E");
    else if (k == 1)
        snprintf(buf, size, "KE");
    else
        snprintf(buf, size, "K%dE", k);
    return buf;
}

const char *bn_layer_name(int layer, int bounces, char *buf, size_t size)
{
    if (layer == bounces + 1)
        snprintf(buf, size, "rest");
    else if (layer > bounces + 1)
        snprintf(buf, size, "L");
    else
        bn_term_name(layer, buf, size);
    return buf;
}

void bn_layers_rest(const double *const *terms, int nterms, const double *L, size_t m, double *rest)
{
    for (size_t j = 0; j < m; j++) {
        double partial = 0;
        for (int k = 0; k < nterms; k++)
            partial += terms[k][j];
        rest[j] = L[j] - partial;   /* rest <- L - sum_{k<=b} K^k E */
    }
}

void bn_layers_stack(const double *const *terms, const double *L, size_t n, int bounces, double *out)
{
    size_t m = 3 * n, nl = (size_t)bn_layer_count(bounces);
    for (int k = 0; k <= bounces; k++)
        memcpy(out + (size_t)k * m, terms[k], m * sizeof(double));
    bn_layers_rest(terms, bounces + 1, L, m, out + (size_t)(bounces + 1) * m);
    memcpy(out + (nl - 1) * m, L, m * sizeof(double));
}
