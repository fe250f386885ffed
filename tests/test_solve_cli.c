/* `bounce solve` end to end: the furnace box (L = Le / (1 - rho), K^k E = rho^k E), rho = 1
 * refused with exit 5, the Cornell box solved by every method against direct, the log, exit codes.
 * Form factors by Monte Carlo with few samples on small meshes keep each test to seconds; the
 * tolerances take F's measured row-sum error delta (from the CSV's ff_row_sum_* keys) into account. */
#include "bn_test.h"

#include <stdint.h>

static double key(const char *text, const char *name)
{
    char pat[128];
    const char *p;
    snprintf(pat, sizeof pat, "# %s=", name);
    p = strstr(text, pat);
    if (!p)
        BN_FAIL("key %s missing", name);
    return strtod(p + strlen(pat), NULL);
}

/* Column `col` of every data row (after the header starting with `patch,`). */
static double *column(const char *text, int col, size_t *n)
{
    const char *p = strstr(text, "\npatch,");
    double *v = NULL;
    size_t cap = 0;
    *n = 0;
    if (!p)
        BN_FAIL("no header row");
    p = strchr(p + 1, '\n');
    while (p && p[1]) {
        const char *q = p + 1;
        for (int c = 0; c < col; c++)
            q = strchr(q, ',') + 1;
        if (*n == cap)
            v = realloc(v, (cap = cap ? 2 * cap : 256) * sizeof(double));
        v[(*n)++] = strtod(q, NULL);
        p = strchr(p + 1, '\n');
    }
    return v;
}

static void write_scene(const char *kd)
{
    char *obj = bn_test_read_file(bn_test_path("meshes/furnace-box.obj"), NULL), *p;
    FILE *fp;
    BN_ASSERT(obj != NULL);
    p = strstr(obj, "mtllib furnace-box.mtl");
    BN_ASSERT(p != NULL);
    fp = fopen(bn_test_tmp("box.obj"), "w");
    fwrite(obj, 1, (size_t)(p - obj), fp);
    fprintf(fp, "mtllib box.mtl");
    fputs(p + strlen("mtllib furnace-box.mtl"), fp);
    fclose(fp);
    fp = fopen(bn_test_tmp("box.mtl"), "w");
    fprintf(fp, "newmtl furnace\nKd %s %s %s\nKe 1 1 1\n", kd, kd, kd);
    fclose(fp);
    free(obj);
}

BN_TEST(cli_rho_1_closed_box_exit_5)
{
    char cmd[4096], *out = NULL;
    int rc;
    write_scene("1");
    snprintf(cmd, sizeof cmd, "solve %s --patches 24 -o %s --log %s", bn_test_tmp("box.obj"), bn_test_tmp("out.csv"),
             bn_test_tmp("conv.csv"));
    rc = bn_test_bounce(cmd, &out);
    fprintf(stderr, "%s", out);
    BN_ASSERT_EQ(rc, 5);
    BN_ASSERT(strstr(out, "singular") != NULL);
    BN_ASSERT(!bn_test_file_exists(bn_test_tmp("out.csv")));
    BN_ASSERT(strstr(out, "nan") == NULL);
    free(out);
    out = bn_test_read_file(bn_test_tmp("conv.csv"), NULL);
    BN_ASSERT(out && strstr(out, "# stop_reason=singular") != NULL);
    free(out);
}

BN_TEST(cli_furnace_box_terms)
{
    char cmd[4096], *out = NULL, *text;
    size_t n;
    double delta, *L, *E, *KE, *K2E, *K3E;
    write_scene("0.5");
    snprintf(cmd, sizeof cmd, "solve %s --patches 54 --method neumann --tol 1e-9 -n 3 -o %s", bn_test_tmp("box.obj"),
             bn_test_tmp("out.csv"));
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
    free(out);
    text = bn_test_read_file(bn_test_tmp("out.csv"), NULL);
    BN_ASSERT(strstr(text, "\npatch,face,material,area,L_R,L_G,L_B,E_R,E_G,E_B,KE_R,KE_G,KE_B,K2E_R,K2E_G,K2E_B,"
                           "K3E_R,K3E_G,K3E_B\n") != NULL);
    delta = fmax(key(text, "ff_row_sum_max") - 1, 1 - key(text, "ff_row_sum_min"));
    fprintf(stderr, "furnace box: F row-sum error delta = %.3g; bound on L: rho delta/(1-rho) = %.3g\n", delta, delta);
    L = column(text, 4, &n);
    E = column(text, 7, &n);
    KE = column(text, 10, &n);
    K2E = column(text, 13, &n);
    K3E = column(text, 16, &n);
    BN_ASSERT_EQ(n, key(text, "patches"));
    for (size_t i = 0; i < n; i++) {
        /* solver error (tail bound <= tol ||E|| = 1e-9 absolute) + F error + 9-digit printing */
        BN_ASSERT_REL(L[i], 2.0, 0.5 * delta / 0.5 + 1e-9 + 1e-8);
        BN_ASSERT_REL(E[i], 1.0, 1e-9);
        BN_ASSERT_REL(KE[i], 0.5, 1 * delta + 1e-8);
        BN_ASSERT_REL(K2E[i], 0.25, 2 * delta + 1e-8);
        BN_ASSERT_REL(K3E[i], 0.125, 3 * delta + 1e-8);
    }
    free(L);
    free(E);
    free(KE);
    free(K2E);
    free(K3E);
    free(text);
}

/* The Cornell box: every method agrees with direct to the tolerance asked; Gauss-Seidel needs
 * fewer sweeps than Jacobi; the log shows the residual falling to the tolerance. */
BN_TEST(cli_cornell_methods_agree)
{
    const char *methods[] = {"direct", "jacobi", "gauss-seidel", "neumann"};
    double *Ld[3] = {NULL, NULL, NULL}, tol = 1e-8;
    size_t n = 0, it[4] = {0, 0, 0, 0};
    for (int q = 0; q < 4; q++) {
        char cmd[4096], *out = NULL, *text, *logt, *last, *p;
        double *L[3], knorm, normE, err = 0, allowed, lmax = 0;
        snprintf(cmd, sizeof cmd,
                 "solve %s --unit mm --patches 300 --ff montecarlo --samples 16 --method %s --tol %g -o %s --log %s",
                 bn_test_path("meshes/cornell-box.obj"), methods[q], tol, bn_test_tmp("out.csv"), bn_test_tmp("conv.csv"));
        BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 0);
        fprintf(stderr, "%s", out);
        free(out);
        text = bn_test_read_file(bn_test_tmp("out.csv"), NULL);
        for (int c = 0; c < 3; c++)
            L[c] = column(text, 4 + c, &n);
        it[q] = (size_t)key(text, "iterations");
        knorm = key(text, "k_norm_inf");
        logt = bn_test_read_file(bn_test_tmp("conv.csv"), NULL);
        normE = key(logt, "norm_E");
        BN_ASSERT(strstr(logt, "# stop_reason=") != NULL);
        BN_ASSERT(strstr(logt, q ? "# stop_reason=converged-rtol" : "# stop_reason=direct") != NULL);
        /* the last row's residual is within the tolerance */
        last = strstr(logt, "# stop_reason=");
        *last = '\0';
        p = strrchr(logt, '\n');
        *p = '\0';
        p = strrchr(logt, '\n');
        BN_ASSERT_LE(strtod(strchr(p, ',') + 1, NULL), tol * normE);
        if (q == 0) {
            for (int c = 0; c < 3; c++)
                Ld[c] = L[c];
        } else {
            for (int c = 0; c < 3; c++) {
                for (size_t i = 0; i < n; i++) {
                    err = fmax(err, fabs(L[c][i] - Ld[c][i]));
                    lmax = fmax(lmax, fabs(Ld[c][i]));
                }
                free(L[c]);
            }
            /* ||L - L*|| <= tol ||E|| / (1 - ||K||), plus 9-digit printing */
            allowed = tol * normE / (1 - knorm) + 1e-8 * lmax;
            fprintf(stderr, "%-12s %5zu iterations: ||L - L_direct||_inf = %.3g <= %.3g\n", methods[q], it[q], err, allowed);
            BN_ASSERT_LE(err, allowed);
        }
        free(text);
        free(logt);
    }
    fprintf(stderr, "Cornell box, tol %g: jacobi %zu sweeps, gauss-seidel %zu, neumann %zu terms\n", tol, it[1], it[2], it[3]);
    BN_ASSERT_LT(it[2], it[1]);
    for (int c = 0; c < 3; c++)
        free(Ld[c]);
}

BN_TEST(cli_exit_codes)
{
    char cmd[4096], *out = NULL;
    write_scene("0.9");
    snprintf(cmd, sizeof cmd, "solve %s --patches 24", bn_test_tmp("box.obj"));
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 2);   /* no -o */
    BN_ASSERT(strstr(out, "-o") != NULL);
    free(out);
    snprintf(cmd, sizeof cmd, "solve %s --patches 24 --method cg -o %s", bn_test_tmp("box.obj"), bn_test_tmp("o.csv"));
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 2);
    free(out);
    snprintf(cmd, sizeof cmd, "solve %s --patches 24 --method jacobi --max-iter 3 -o %s", bn_test_tmp("box.obj"),
             bn_test_tmp("o.csv"));
    BN_ASSERT_EQ(bn_test_bounce(cmd, &out), 5);   /* not converged within the limit */
    BN_ASSERT(strstr(out, "iteration-limit") != NULL && strstr(out, "predicted") != NULL);
    BN_ASSERT(!bn_test_file_exists(bn_test_tmp("o.csv")));
    free(out);
    BN_ASSERT_EQ(bn_test_bounce("solve --help", &out), 0);
    BN_ASSERT(strstr(out, "auto (default): gauss-seidel") && strstr(out, "default 1e-6") && strstr(out, "default 100000"));
    free(out);
}

/* Warnings of one code beyond the first 5 are gathered into one line at the end (a real asset's
 * thousands of back-to-back faces must not flood the terminal): 12 thin panels, each two faces back
 * to back, floating in the furnace box, give 5 [back-to-back] lines and "7 more like the 5 above
 * (12 in all". */
BN_TEST(cli_warnings_gathered_by_code)
{
    char cmd[4096], *out = NULL, *p;
    FILE *fp;
    int lines = 0, rc;
    write_scene("0.5");
    fp = fopen(bn_test_tmp("box.obj"), "a");
    BN_ASSERT(fp != NULL);
    fprintf(fp, "\nusemtl furnace\n");
    for (int k = 0; k < 12; k++) {
        double x = 0.1 + 0.07 * k;
        fprintf(fp, "v %g 0.3 0.4\nv %g 0.3 0.45\nv %g 0.35 0.45\nv %g 0.35 0.4\n", x, x, x, x);
        fprintf(fp, "f -4 -3 -2 -1\nf -1 -2 -3 -4\n");
    }
    fclose(fp);
    snprintf(cmd, sizeof cmd, "info %s", bn_test_tmp("box.obj"));
    rc = bn_test_bounce(cmd, &out);
    BN_ASSERT_EQ(rc, 0);
    for (p = out; (p = strstr(p, "[back-to-back]")) != NULL; p++)
        lines++;
    fprintf(stderr, "%d [back-to-back] lines\n", lines);
    BN_ASSERT_EQ(lines, 6);
    BN_ASSERT(strstr(out, "7 more like the 5 above (12 in all") != NULL);
    free(out);
}
