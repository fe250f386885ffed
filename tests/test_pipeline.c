/* The pipeline as a library user calls it: scene file to solution with every term, in any storage,
 * against the white furnace's analytic answer (closed cube, rho 0.5, Le 1: L = Le / (1 - rho) = 2,
 * K^k E = rho^k Le, rest = rho^(b+1) / (1 - rho) Le); stages that fail leave nothing to leak. */
#include "bn_test.h"
#include "bounce/pipeline.h"

static void furnace(const char *storage, bn_precision prec)
{
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_error err;
    const int b = 4;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    o.mesh.target_patches = 96;
    o.ff.storage = storage;
    o.ff.precision = prec;
    o.ff.quiet = 1;
    o.solve.quiet = 1;
    o.solve.bounces = b;
    o.solve.tol = 1e-12;
    o.threads = 2;
    if (bn_pipeline_run(bn_test_path("meshes/furnace-box.obj"), &o, &p, &err) != BN_OK)
        BN_FAIL("%s/%s: %s", storage, bn_precision_name(prec), err.msg);
    BN_ASSERT_GT(p.n, 48);
    BN_ASSERT(p.rt == NULL);   /* released after K unless keep_rt */
    BN_ASSERT_EQ(p.res.nterms, b + 1);
    for (size_t i = 0; i < 3 * p.n; i++) {
        double rk = 1;
        /* the analytic form factors' row sums are exact to ~1e-6 (x 1 / (1 - rho) = 2) */
        BN_ASSERT_REL(p.res.L[i], 2.0, 1e-5);
        for (int k = 0; k <= b; k++, rk *= 0.5)
            BN_ASSERT_REL(p.res.terms[k][i], rk, 1e-5);
        BN_ASSERT_REL(p.rest[i], pow(0.5, b + 1) / 0.5, 1e-4);
    }
    BN_ASSERT(strstr(bn_transport_name(p.k), strcmp(storage, "dense") == 0 ? "dense" : "csr") != NULL);
    BN_ASSERT_GE(p.seconds_load, 0);
    BN_ASSERT_GT(p.seconds_operator, 0);
    bn_pipeline_free(&p);
    bn_pipeline_free(&p);   /* twice is harmless: it zeroes what it frees */
}

BN_TEST(furnace_dense_float) { furnace("dense", BN_PRECISION_FLOAT); }
BN_TEST(furnace_sparse_double) { furnace("sparse", BN_PRECISION_DOUBLE); }

BN_TEST(stages_fail_cleanly)
{
    bn_pipeline_opts o;
    bn_pipeline p;
    bn_error err;
    bn_pipeline_opts_default(&o);
    o.load.log.quiet = 1;
    BN_ASSERT_STATUS(bn_pipeline_run(bn_test_path("meshes/no-such-scene.obj"), &o, &p, &err), BN_EIO);
    BN_ASSERT(p.scene == NULL && p.k == NULL && p.res.L == NULL);
    bn_pipeline_free(&p);
    o.ff.storage = "tiled";
    o.ff.quiet = 1;
    BN_ASSERT_STATUS(bn_pipeline_run(bn_test_path("meshes/furnace-box.obj"), &o, &p, &err), BN_EUSAGE);
    BN_ASSERT(strstr(err.msg, "unknown storage 'tiled'") != NULL);
    BN_ASSERT(p.scene != NULL && p.k == NULL);   /* the scene stage had run */
    bn_pipeline_free(&p);
}
