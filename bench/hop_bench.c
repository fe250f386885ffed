/* The hierarchy's frozen operator against the machine's memory bandwidth (issue 35): a scene solved
 * with the hierarchical transport, then F_H applied to a vector again and again, timed alone. The
 * application streams each link once (its source node and F, 4 + 4 bytes, and the direction, 2 more,
 * for links into clusters) and the source and receiver vectors once (x and y, 3 doubles a patch);
 * those bytes over the median time, against a STREAM-like triad measured in the same run (target:
 * 60% or more), on every thread and on one. Prints a markdown table. Not a test.
 *
 *   hop_bench [SCENE] [--unit m|cm|mm] [--eps E] [--reps R]
 *
 * Defaults: meshes/cornell-box.obj, mm, eps 2e-5 (about 9 M links), ray visibility (the links' values
 * do not change what an application costs), 15 repetitions. */
#include "bounce/pipeline.h"
#include "bounce/transport.h"
#include "base/internal.h"
#include "triad.h"

#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int usage(const char *why)
{
    fprintf(stderr, "hop_bench: %s\nusage: hop_bench [SCENE] [--unit m|cm|mm] [--eps E] [--reps R]\n", why);
    return 2;
}

static int hop_args(int argc, char **argv, bn_pipeline_opts *o, const char **scene, int *reps)
{
    for (int i = 1; i < argc; i++) {
        char *end = NULL;
        if (argv[i][0] != '-') {
            *scene = argv[i];
            continue;
        }
        if (i + 1 >= argc)
            return usage("an option without its value");
        if (!strcmp(argv[i], "--unit")) {
            if (bn_unit_parse(argv[++i], &o->load.unit))
                return usage("--unit takes m, cm or mm");
        } else if (!strcmp(argv[i], "--eps")) {
            o->hier.eps = strtod(argv[++i], &end);
            if (*end || !(o->hier.eps > 0))
                return usage("--eps takes a positive number");
        } else if (!strcmp(argv[i], "--reps")) {
            long n = strtol(argv[++i], &end, 10);
            if (*end || n < 1 || n > 32)
                return usage("--reps takes a whole number from 1 to 32");
            *reps = (int)n;
        } else
            return usage("unknown option");
    }
    return 0;
}

/* The bytes one application streams: the links (8 bytes, 10 into clusters), x and y. */
static double hop_bytes(const bn_transport *k, size_t *nlinks)
{
    bn_transport_links lk;
    bn_error err;
    size_t into_clusters = 0;
    if (bn_transport_links_get(k, &lk, &err) != BN_OK) {
        fprintf(stderr, "hop_bench: %s\n", err.msg);
        exit(1);
    }
    for (size_t v = 0; v < lk.nnodes; v++)
        if (lk.cluster[v])
            into_clusters += lk.start[v + 1] - lk.start[v];
    *nlinks = lk.nlinks;
    double bytes = 8.0 * (double)lk.nlinks + 2.0 * (double)into_clusters + 2.0 * 24.0 * (double)lk.npatch;
    bn_transport_links_free(&lk);
    return bytes;
}

/* The median seconds of one application of F_H on `threads` threads. */
static double hop_time(const bn_transport *k, const double *x, double *y, int threads, int reps)
{
    double t[32];
    bn_error err;
    omp_set_num_threads(threads);
    bn_transport_apply_F(k, x, y, &err);   /* warm: caches, pages */
    for (int r = 0; r < reps; r++) {
        double t0 = bn__now();
        if (bn_transport_apply_F(k, x, y, &err) != BN_OK) {
            fprintf(stderr, "hop_bench: %s\n", err.msg);
            exit(1);
        }
        t[r] = bn__now() - t0;
    }
    return bench_median(t, reps);
}

int main(int argc, char **argv)
{
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_error err;
    const char *scene = BN_SOURCE_DIR "/meshes/cornell-box.obj";
    int reps = 15, threads = omp_get_max_threads();
    size_t nlinks = 0;
    bn_pipeline_opts_default(&o);
    o.load.unit = BN_UNIT_MM;
    o.mesh_auto = 1;
    o.method_auto = 1;
    o.transport = "hierarchical";
    o.hier.eps = 2e-5;
    o.ff.exact_visibility = 0;
    o.solve.bounces = 1;
    int rc = hop_args(argc, argv, &o, &scene, &reps);
    if (rc)
        return rc;
    if (bn_pipeline_run(scene, &o, &p, &err) != BN_OK) {
        fprintf(stderr, "hop_bench: %s\n", err.msg);
        return 1;
    }
    size_t n = bn_transport_size(p.k);
    double *x = malloc(3 * n * sizeof(double)), *y = malloc(3 * n * sizeof(double));
    if (!x || !y)
        return usage("out of memory for the vectors");
    for (size_t i = 0; i < 3 * n; i++)
        x[i] = 1.0 + (double)(i % 7) / 7.0;
    double bytes = hop_bytes(p.k, &nlinks);
    double tn = hop_time(p.k, x, y, threads, reps), t1 = hop_time(p.k, x, y, 1, reps);
    omp_set_num_threads(threads);
    double triad = bench_triad_gbs((size_t)1 << 25, 9);
    omp_set_num_threads(1);
    double triad1 = bench_triad_gbs((size_t)1 << 25, 9);
    printf("# hop_bench: %s, %zu patches, eps %g: %zu links, %.1f MB streamed per application\n\n", scene, n,
           o.hier.eps, nlinks, bytes / 1e6);
    printf("| threads | apply ms (median of %d) | links/s | GB/s | triad GB/s | / triad |\n", reps);
    printf("|---|---|---|---|---|---|\n");
    for (int r = 0; r < 2; r++) {
        double t = r ? t1 : tn, tr = r ? triad1 : triad;
        printf("| %d | %.2f | %.3g | %.1f | %.1f | %.0f%% |\n", r ? 1 : threads, 1e3 * t, (double)nlinks / t,
               bytes / t / 1e9, tr, 100 * bytes / t / 1e9 / tr);
    }
    free(x);
    free(y);
    bn_pipeline_free(&p);
    return 0;
}
