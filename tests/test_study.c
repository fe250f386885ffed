/* Tests of `bounce study`: the CSV and its provenance, the truncation bound row by row, the exact
 * furnace answer, mesh-size convergence toward the reference, and the plot files.
 *
 * Tolerances, with their reasons:
 *  - ROUND: measured ||L - S_n||_inf may exceed a tight bound by the double rounding of L and S_n
 *    (a few ulps of ||L||); the test allows the reference's own a posteriori error bound plus 1e-12
 *    relative, nothing more.
 *  - FURNACE: with hemisphere form factors in a closed box every ray hits, so each row of F sums to 1
 *    up to float storage (~6e-8 per row); over the <= 40 applications in the study that is below 1e-5
 *    relative in K^k E = rho^k E. */
#include "bn_test.h"

#include <ctype.h>
#include "bounce/study.h"

#include <stdint.h>

#define ROUND 1e-12
#define FURNACE 1e-5

/* ---- a small CSV reader: '#' lines skipped (kept in *meta), header, rows of fields ---- */
typedef struct csv {
    char *text;
    char *meta;          /* the '#' lines, concatenated */
    int ncol, nrow;
    char *col[128];
    char *cell[512][128];
} csv;

static csv *csv_read(const char *path)
{
    size_t size;
    char *t = bn_test_read_file(path, &size), *line, *save = NULL;
    csv *c;
    int header = 0;
    if (!t)
        BN_FAIL("cannot read %s", path);
    c = calloc(1, sizeof *c);
    c->text = t;
    c->meta = calloc(size + 1, 1);
    for (line = strtok_r(t, "\n", &save); line; line = strtok_r(NULL, "\n", &save)) {
        char *f, *s2 = NULL;
        int k = 0;
        if (line[0] == '#') {
            strcat(c->meta, line);
            strcat(c->meta, "\n");
            continue;
        }
        for (f = strtok_r(line, ",", &s2); f && k < 128; f = strtok_r(NULL, ",", &s2), k++) {
            if (!header)
                c->col[k] = f;
            else
                c->cell[c->nrow][k] = f;
        }
        if (!header) {
            c->ncol = k;
            header = 1;
        } else {
            BN_ASSERT_EQ(k, c->ncol);   /* every row has every column */
            if (++c->nrow >= 512)
                break;
        }
    }
    return c;
}

static int csv_col(const csv *c, const char *name)
{
    for (int k = 0; k < c->ncol; k++)
        if (strcmp(c->col[k], name) == 0)
            return k;
    BN_FAIL("column %s missing", name);
    return -1;
}

static double csv_num(const csv *c, int row, const char *name) { return strtod(c->cell[row][csv_col(c, name)], NULL); }
static const char *csv_str(const csv *c, int row, const char *name) { return c->cell[row][csv_col(c, name)]; }

static double meta_num(const csv *c, const char *key)
{
    char pat[128];
    const char *p;
    snprintf(pat, sizeof pat, "# %s=", key);
    p = strstr(c->meta, pat);
    if (!p)
        BN_FAIL("provenance line %s missing", key);
    return strtod(p + strlen(pat), NULL);
}

/* The text of an SVG's <text> elements, entities decoded (non-ASCII as '?'), joined by '|'. */
static char *svg_text(const char *path)
{
    char *s = bn_test_read_file(path, NULL), *out, *w;
    const char *p;
    if (!s)
        BN_FAIL("cannot read %s", path);
    out = calloc(strlen(s) + 2, 1);
    w = out;
    for (p = strstr(s, "<text"); p; p = strstr(p, "<text")) {
        const char *e;
        p = strchr(p, '>');
        if (!p)
            break;
        e = strstr(++p, "</text>");
        if (!e)
            break;
        while (p < e) {
            if (*p == '<') {   /* nested tspan tags */
                p = strchr(p, '>') + 1;
            } else if (strncmp(p, "&#x", 3) == 0) {
                unsigned long u = strtoul(p + 3, NULL, 16);
                *w++ = u < 128 ? (char)u : '?';
                p = strchr(p, ';') + 1;
            } else {
                *w++ = *p++;
            }
        }
        *w++ = '|';
    }
    free(s);
    return out;
}

/* The decade tick labels ("10-3", "100", "102" as PLplot writes 10^k without the superscript)
 * of a plot's text: is there one within a decade of v? */
static int has_decade_near(const char *text, double v)
{
    double lv = log10(v);
    for (const char *p = text; (p = strstr(p, "|10")) != NULL; p += 3) {
        char *end;
        long k = strtol(p + 3, &end, 10);
        if (*end != '|')
            continue;
        if (end == p + 3)
            k = 1;   /* "10" itself */
        if (fabs((double)k - lv) <= 1)
            return 1;
    }
    return 0;
}

static void csv_free(csv *c)
{
    free(c->text);
    free(c->meta);
    free(c);
}

/* The header is BN_STUDY_CSV_COLUMNS followed by one err_surf_<material> per material. */
static void check_columns(const csv *c, const char *const *materials, int nmat)
{
    char expect[2048], got[2048] = "";
    snprintf(expect, sizeof expect, "%s", BN_STUDY_CSV_COLUMNS);
    for (int m = 0; m < nmat; m++) {
        strcat(expect, ",err_surf_");
        strcat(expect, materials[m]);
    }
    for (int k = 0; k < c->ncol; k++) {
        if (k)
            strcat(got, ",");
        strcat(got, c->col[k]);
    }
    if (strcmp(expect, got) != 0)
        BN_FAIL("header\n  %s\nexpected\n  %s", got, expect);
}

BN_TEST(study_truncation_bound_cornell)
{
    /* The default (analytic) form factors; the reference is the direct solve of that same K. */
    char args[1024], *out = NULL;
    const char *mats[] = {"white", "red", "green", "light"};
    csv *c;
    int rows = 0;
    double prev = INFINITY, ref_abs, normL;
    snprintf(args, sizeof args,
             "study %s --unit mm --patches 150 --vary bounces=0,1,2,3,4,5,6,7,8,9,10,11,"
             "12,13,14,15,16,17,18,19,20 --methods gauss-seidel,direct --tols 1e-3,1e-6 -o %s --plot %s --threads 2",
             bn_test_path("meshes/cornell-box.obj"), bn_test_tmp("trunc.csv"), bn_test_tmp("trunc"));
    if (bn_test_bounce(args, &out) != 0)
        BN_FAIL("bounce study failed:\n%s", out ? out : "");
    c = csv_read(bn_test_tmp("trunc.csv"));
    check_columns(c, mats, 4);
    BN_ASSERT(bn_test_file_exists(bn_test_tmp("trunc.png")));   /* its content: the SVG's, checked below */
    /* provenance: how it was made */
    BN_ASSERT(strstr(c->meta, "# command=") && strstr(c->meta, "# version=") && strstr(c->meta, "# seed=1"));
    BN_ASSERT(strstr(c->meta, "# solver=") && strstr(c->meta, "# tolerance=") && strstr(c->meta, "# reference=direct"));
    normL = meta_num(c, "norm_L");
    ref_abs = meta_num(c, "reference_error") * normL;
    BN_ASSERT_LT(ref_abs, 1e-9 * normL);   /* the reference is exact to rounding */
    for (int r = 0; r < c->nrow; r++) {
        double e, b, bk;
        if (strcmp(csv_str(c, r, "method"), "truncated") != 0)
            continue;
        BN_ASSERT_EQ(csv_num(c, r, "x"), rows);
        e = csv_num(c, r, "err_inf");
        b = csv_num(c, r, "bound");
        bk = csv_num(c, r, "bound_ke");
        /* the a priori bounds hold, row by row */
        BN_ASSERT_LE(e, b + ref_abs + ROUND * normL);
        BN_ASSERT_LE(e, bk + ref_abs + ROUND * normL);
        /* K >= 0 and E >= 0: S_n grows toward L entry by entry, so the error never grows */
        BN_ASSERT_LE(e, prev);
        BN_ASSERT_GT(e, 0);
        prev = e;
        rows++;
    }
    BN_ASSERT_EQ(rows, 21);
    /* The plot shows what the table says: the series and the bound in its legend, the axis of
     * bounces, and decade ticks within a decade of the smallest and largest truncation error. */
    {
        char *t = svg_text(bn_test_tmp("trunc.svg"));
        double emax = 0, emin = INFINITY;
        for (int r = 0; r < c->nrow; r++)
            if (strcmp(csv_str(c, r, "method"), "truncated") == 0) {
                emax = fmax(emax, csv_num(c, r, "err_inf"));
                emin = fmin(emin, csv_num(c, r, "err_inf"));
            }
        BN_ASSERT(strstr(t, "|truncated series|") != NULL);
        BN_ASSERT(strstr(t, "|bound ||K||n+1/(1-||K||) ||E|||") != NULL);
        BN_ASSERT(strstr(t, "bounces n") != NULL);
        BN_ASSERT(has_decade_near(t, emax));   /* err_inf: W m^-2 sr^-1, as the axis */
        BN_ASSERT(has_decade_near(t, emin));
        free(t);
    }
    /* Gauss-Seidel reaches each tolerance: rows for both, and its error is below the bound of its
     * residual (||L - L_k|| <= ||r|| / (1 - ||K||) <= tol ||E|| / (1 - ||K||)). */
    {
        int gs = 0;
        double kn = meta_num(c, "k_norm_inf"), nE = meta_num(c, "norm_E");
        for (int r = 0; r < c->nrow; r++)
            if (strcmp(csv_str(c, r, "method"), "gauss-seidel") == 0) {
                double tol = csv_num(c, r, "x");
                BN_ASSERT_LE(csv_num(c, r, "err_inf"), tol * nE / (1 - kn) + ref_abs);
                gs++;
            }
        BN_ASSERT_EQ(gs, 2);
    }
    csv_free(c);
    free(out);
}

BN_TEST(study_truncation_furnace_exact)
{
    /* Closed furnace box, rho = 0.5, Le = 1: L = 2 and S_n = 2 - 0.5^n exactly, so ||L - S_n|| = 0.5^n,
     * which is also the bound (||K|| = rho) and the spectral estimate: the bound is tight here. */
    char args[1024], *out = NULL;
    const char *mats[] = {"furnace"};
    csv *c;
    int rows = 0;
    snprintf(args, sizeof args,
             "study %s --patches 24 --ff hemisphere --vary bounces=0,1,2,5,10,20 --methods direct -o %s -q",
             bn_test_path("meshes/furnace-box.obj"), bn_test_tmp("furnace.csv"));
    if (bn_test_bounce(args, &out) != 0)
        BN_FAIL("bounce study failed:\n%s", out ? out : "");
    c = csv_read(bn_test_tmp("furnace.csv"));
    check_columns(c, mats, 1);
    BN_ASSERT_REL(meta_num(c, "norm_L"), 2.0, FURNACE);
    BN_ASSERT_REL(meta_num(c, "k_norm_inf"), 0.5, FURNACE);
    for (int r = 0; r < c->nrow; r++) {
        double n, exact;
        if (strcmp(csv_str(c, r, "method"), "truncated") != 0)
            continue;
        n = csv_num(c, r, "x");
        exact = pow(0.5, n);
        BN_ASSERT_REL(csv_num(c, r, "err_inf"), exact, FURNACE);
        BN_ASSERT_REL(csv_num(c, r, "bound"), exact, FURNACE);
        BN_ASSERT_REL(csv_num(c, r, "estimate"), exact, FURNACE);
        /* every surface mean is off by the same 0.5^n / 2 */
        BN_ASSERT_REL(csv_num(c, r, "err_surface_max"), exact / 2, FURNACE);
        rows++;
    }
    BN_ASSERT_EQ(rows, 6);
    csv_free(c);
    free(out);
}

BN_TEST(study_mesh_converges)
{
    /* Mesh-size study on coarse settings against a finer radiosity reference: the per-surface and
     * per-patch errors shrink as the mesh is refined, and the reference's estimated error is below
     * the errors it measures (otherwise the study would compare against noise). */
    char args[1024], *out = NULL;
    csv *c;
    double prev_s = INFINITY, prev_r = INFINITY, ref_err;
    int rows = 0;
    snprintf(args, sizeof args,
             "study %s --unit mm --vary patches=20,80 --ref-patches 640 --samples 8 -o %s -q",
             bn_test_path("meshes/cornell-box.obj"), bn_test_tmp("mesh.csv"));
    if (bn_test_bounce(args, &out) != 0)
        BN_FAIL("bounce study failed:\n%s", out ? out : "");
    c = csv_read(bn_test_tmp("mesh.csv"));
    ref_err = meta_num(c, "reference_error");
    for (int r = 0; r < c->nrow; r++) {
        double es = csv_num(c, r, "err_surface_max"), er = csv_num(c, r, "err_rms_rel");
        BN_ASSERT_EQ(csv_num(c, r, "ground"), 1);   /* compared on the reference's patches */
        BN_ASSERT_LT(es, prev_s);
        BN_ASSERT_LT(er, prev_r);
        BN_ASSERT_LT(ref_err, es);
        BN_ASSERT_GT(csv_num(c, r, "t_ff"), 0);
        BN_ASSERT_GT(csv_num(c, r, "peak_mb"), 0);
        prev_s = es;
        prev_r = er;
        rows++;
    }
    BN_ASSERT_EQ(rows, 2);
    csv_free(c);
    free(out);
}

BN_TEST(study_eps_against_the_tracer)
{
    /* The hierarchy's accuracy knob against the light itself: --vary eps with --against-spp takes the
     * path tracer on the study's own mesh as the reference (not dense K, which would measure K_H alone),
     * compares every row patch by patch on that mesh (ground 0), and the hierarchy's error falls as eps
     * falls, towards the radiosity discretisation the tracer does not share. */
    char args[1024], *out = NULL;
    csv *c;
    int hier = 0, trace = 0;
    double e_coarse = NAN, e_fine = NAN;
    snprintf(args, sizeof args,
             "study %s --unit mm --vary eps=2e-2,5e-4 --transport hierarchical --patches 300 --against-spp 16,64 "
             "--metric patch --ref-spp 1024 --target 0.2 -o %s -q",
             bn_test_path("meshes/cornell-box.obj"), bn_test_tmp("eps.csv"));
    if (bn_test_bounce(args, &out) != 0)
        BN_FAIL("bounce study failed:\n%s", out ? out : "");
    /* direct needs entries, which K_H does not offer: the study says what ran in its place */
    if (!strstr(out, "direct needs entries of K") || !strstr(out, "jacobi to tol"))
        BN_FAIL("no word of jacobi standing in for direct on the hierarchy:\n%s", out);
    c = csv_read(bn_test_tmp("eps.csv"));
    BN_ASSERT(strstr(c->meta, "# reference=path tracer") != NULL);
    for (int r = 0; r < c->nrow; r++) {
        const char *m = csv_str(c, r, "method");
        BN_ASSERT_EQ(csv_num(c, r, "ground"), 0);   /* the reference's own mesh */
        BN_ASSERT_EQ(csv_num(c, r, "patches"), meta_num(c, "reference_patches"));
        if (strcmp(m, "hierarchy") == 0) {
            if (csv_num(c, r, "x") > 1e-2)
                e_coarse = csv_num(c, r, "err_rms_rel");
            else
                e_fine = csv_num(c, r, "err_rms_rel");
            hier++;
        } else if (strcmp(m, "trace") == 0)
            trace++;
    }
    BN_ASSERT_EQ(hier, 2);
    BN_ASSERT_EQ(trace, 2);
    BN_ASSERT_LT(e_fine, e_coarse);
    csv_free(c);
    free(out);
}

BN_TEST(study_plot_files)
{
    char args[1024], *out = NULL, *png, *svg;
    size_t npng, nsvg;
    static const unsigned char magic[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    snprintf(args, sizeof args,
             "study %s --patches 24 --ff hemisphere --vary bounces=0,1,2,3,4 --methods jacobi,direct -o %s --plot %s -q",
             bn_test_path("meshes/furnace-box.obj"), bn_test_tmp("plot.csv"), bn_test_tmp("plot"));
    if (bn_test_bounce(args, &out) != 0)
        BN_FAIL("bounce study failed:\n%s", out ? out : "");
    png = bn_test_read_file(bn_test_tmp("plot.png"), &npng);
    svg = bn_test_read_file(bn_test_tmp("plot.svg"), &nsvg);
    BN_ASSERT(png && svg);
    BN_ASSERT_GT(npng, 1000);
    BN_ASSERT(memcmp(png, magic, 8) == 0);
    BN_ASSERT(strstr(svg, "<svg") != NULL && strstr(svg, "</svg>") != NULL);
    BN_ASSERT(strncmp(svg, "<?xml", 5) == 0 || strncmp(svg, "<svg", 4) == 0);
    /* no temporary left behind (atomic writes go to a ".NAME.tmpPID" beside the target, then rename) */
    snprintf(args, sizeof args, "ls -a '%s' | grep -q '\\.tmp'", bn_test_tmpdir());
    BN_ASSERT(bn_test_run(args, NULL) != 0);
    free(png);
    free(svg);
    free(out);
}

BN_TEST(study_usage_errors)
{
    char args[512], *out = NULL;
    snprintf(args, sizeof args, "study %s --vary colour=1,2 -o %s", bn_test_path("meshes/furnace-box.obj"),
             bn_test_tmp("x.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 2);
    BN_ASSERT(out && strstr(out, "unknown parameter 'colour'"));
    free(out);
    snprintf(args, sizeof args, "study %s --vary bounces=1,x -o %s", bn_test_path("meshes/furnace-box.obj"),
             bn_test_tmp("x.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 2);
    free(out);
    snprintf(args, sizeof args, "study %s --vary bounces=-1 -o %s", bn_test_path("meshes/furnace-box.obj"),
             bn_test_tmp("x.csv"));
    BN_ASSERT_EQ(bn_test_bounce(args, &out), 2);
    BN_ASSERT(!bn_test_file_exists(bn_test_tmp("x.csv")));
    free(out);
}

/* Every error column depends on the answers only, never on the thread count: the form factors, the
 * solves and the tracer are bit-identical for any --threads (their streams are keyed by patch and
 * sample), so the study's errors must be too. Times and memory are the only columns allowed to move. */
static void errors_only(const char *path, char *buf, size_t size)
{
    csv *c = csv_read(path);
    static const char *cols[] = {"err_inf", "err_max_rel", "err_rms_rel", "err_energy_rel", "err_surface_max",
                                 "iterations", "se_surface_max"};
    buf[0] = '\0';
    for (int r = 0; r < c->nrow; r++)
        for (size_t k = 0; k < sizeof cols / sizeof cols[0]; k++) {
            strncat(buf, csv_str(c, r, cols[k]), size - strlen(buf) - 2);
            strncat(buf, ",", size - strlen(buf) - 2);
        }
    csv_free(c);
}

BN_TEST(study_threads_identical)
{
    char args[1024], *out = NULL, a[8192], b[8192];
    const char *study[2] = {"--ff hemisphere --samples 512 --vary bounces=0,3,9 --methods gauss-seidel,jacobi --tols 1e-4",
                            "--vary spp=4,16 --ref-patches 60"};
    for (int s = 0; s < 2; s++) {
        for (int t = 1; t <= 2; t++) {
            snprintf(args, sizeof args, "study %s --unit mm --patches 30 %s --threads %d -o %s -q",
                     bn_test_path("meshes/cornell-box.obj"), study[s], t, bn_test_tmp(t == 1 ? "t1.csv" : "t2.csv"));
            if (bn_test_bounce(args, &out) != 0)
                BN_FAIL("bounce study failed:\n%s", out ? out : "");
            free(out);
            out = NULL;
        }
        errors_only(bn_test_tmp("t1.csv"), a, sizeof a);
        errors_only(bn_test_tmp("t2.csv"), b, sizeof b);
        if (strcmp(a, b) != 0)
            BN_FAIL("errors differ between 1 and 2 threads:\n  %s\n  %s", a, b);
    }
}

/* ---- studies a reader can trust ---- */

/* The Cornell box with the study's default arguments (three settings: the default reference, 4x the
 * finest, is then about 1,600 patches instead of 3,123 for a fourth at 800): every per-patch relative error below 1 (the
 * scale cannot vanish under the blocks), the RMS falling with the mesh, the fitted order and the
 * reference's error recorded, a warning exactly when the reference is not 3x better than the best
 * setting, and each kind of warning said at most once. Partly occluded pairs by shadow rays: the
 * study is tested here, the exact visible parts (the default, about 4x this test's time through
 * the 3,123-patch reference) in test_ff_visibility. BN_SLOW: ~7 s. */
BN_TEST(cornell_mesh_study_defaults) /* BN_SLOW */
{
    char args[1024], *out = NULL, *w;
    csv *c;
    double best = INFINITY, rms100 = NAN, rms400 = NAN;
    BN_SKIP_IF_SLOW_RUN();
    snprintf(args, sizeof args, "study %s --unit mm --vary patches=100,200,400 --ff-visibility rays -o %s",
             bn_test_path("meshes/cornell-box.obj"), bn_test_tmp("mesh.csv"));
    if (bn_test_bounce(args, &out) != 0)
        BN_FAIL("bounce study failed:\n%s", out ? out : "");
    c = csv_read(bn_test_tmp("mesh.csv"));
    BN_ASSERT_EQ(c->nrow, 3);
    for (int r = 0; r < c->nrow; r++) {
        BN_ASSERT_LT(csv_num(c, r, "err_max_rel"), 1);
        BN_ASSERT_LE(csv_num(c, r, "err_l1_rel"), csv_num(c, r, "err_rms_rel"));   /* L1 <= L2 (same weights) */
        BN_ASSERT_LE(csv_num(c, r, "err_rms_rel"), csv_num(c, r, "err_max_rel"));
        best = fmin(best, csv_num(c, r, "err_surface_max"));
        if (csv_num(c, r, "x") == 100)
            rms100 = csv_num(c, r, "err_rms_rel");
        if (csv_num(c, r, "x") == 400)
            rms400 = csv_num(c, r, "err_rms_rel");
    }
    BN_ASSERT_LT(rms400, rms100);
    BN_ASSERT_GT(meta_num(c, "reference_order"), 0.5);
    /* the study warns exactly when its reference is not 3x better than the best setting (with the
     * contact cuts the finest setting comes close to the reference's own estimated error) */
    BN_ASSERT_EQ(meta_num(c, "reference_error") * 3 > best, strstr(out, "not well below") != NULL);
    /* each warning kind once: every warning line ends in its code, and no code comes twice */
    for (w = strstr(out, "warning:"); w; w = strstr(w + 1, "warning:")) {
        char code[64], *b;
        size_t n = strcspn(w, "\n");
        const char *open = w + n;
        while (open > w && *open != '[')
            open--;
        BN_ASSERT(*open == '[' && w[n - 1] == ']');
        snprintf(code, sizeof code, "%.*s", (int)(w + n - open), open);
        for (b = strstr(w + 1, "warning:"); b; b = strstr(b + 1, "warning:")) {
            size_t m = strcspn(b, "\n");
            if (m >= strlen(code) && strncmp(b + m - strlen(code), code, strlen(code)) == 0)
                BN_FAIL("the warning %s twice:\n%s", code, out);
        }
    }
    csv_free(c);
    free(out);
}

/* Gauss-Legendre nodes and weights on [0, 1] (Newton on P_n; Golub & Welsch's values to rounding). */
static void gauss01(int n, double *x, double *w)
{
    for (int i = 0; i < n; i++) {
        double z = cos(3.14159265358979323846 * (i + 0.75) / (n + 0.5)), p1, p2, p3, pp = 1;
        for (int it = 0; it < 100; it++) {
            double z1 = z;
            p1 = 1, p2 = 0;
            for (int j = 1; j <= n; j++) {
                p3 = p2;
                p2 = p1;
                p1 = ((2.0 * j - 1) * z * p2 - (j - 1.0) * p3) / j;
            }
            pp = n * (z * p1 - p2) / (z * z - 1);
            z = z1 - p1 / pp;
            if (fabs(z - z1) < 1e-15)
                break;
        }
        x[i] = 0.5 * (1 - z);
        w[i] = 1.0 / ((1 - z * z) * pp * pp);   /* 2 / ((1 - z^2) P'^2), halved for [0, 1] */
    }
}

/* Two unit squares facing each other at gap g, both reflecting rho, the lower emitting Le = 1: the
 * continuum radiosity equation by Nystrom's method on n x n Gauss nodes a plate (the kernel
 * g^2 / (pi r^4) is smooth for g > 0, so this converges spectrally). out: the area means of L on
 * the emitter and the receiver; first: the receiver's first bounce (rho F Le). */
static void plates_nystrom(double g, double rho, int n, double out[2], double *first)
{
    int m = n * n;
    double x[64], w[64], *K = malloc((size_t)m * m * sizeof(double)), *LA = malloc(m * sizeof(double)),
                         *LB = malloc(m * sizeof(double)), *t = malloc(m * sizeof(double));
    gauss01(n, x, w);
    for (int i = 0; i < m; i++)
        for (int j = 0; j < m; j++) {
            double dx = x[i / n] - x[j / n], dz = x[i % n] - x[j % n], r2 = dx * dx + dz * dz + g * g;
            K[(size_t)i * m + j] = g * g / (3.14159265358979323846 * r2 * r2) * w[j / n] * w[j % n];
        }
    for (int i = 0; i < m; i++)
        LA[i] = 1, LB[i] = 0;
    for (int it = 0; it < 200; it++) {   /* L_B = rho K L_A; L_A = Le + rho K L_B (symmetric kernel) */
        for (int i = 0; i < m; i++) {
            double s = 0;
            for (int j = 0; j < m; j++)
                s += K[(size_t)i * m + j] * LA[j];
            t[i] = rho * s;
        }
        memcpy(LB, t, m * sizeof(double));
        if (it == 0) {
            double s = 0;
            for (int i = 0; i < m; i++)
                s += w[i / n] * w[i % n] * LB[i];
            *first = s;
        }
        for (int i = 0; i < m; i++) {
            double s = 0;
            for (int j = 0; j < m; j++)
                s += K[(size_t)i * m + j] * LB[j];
            LA[i] = 1 + rho * s;
        }
    }
    out[0] = out[1] = 0;
    for (int i = 0; i < m; i++) {
        out[0] += w[i / n] * w[i % n] * LA[i];
        out[1] += w[i / n] * w[i % n] * LB[i];
    }
    free(K);
    free(LA);
    free(LB);
    free(t);
}

/* The extrapolated reference of a mesh study against a continuum answer computed here: two
 * reflecting plates, close enough (gap 0.25) for the mesh to matter. The Nystrom solution is first
 * checked against the published factor (Howell C-11 at X = Y = 4: F = 0.6188 ... for gap 0.25, whose
 * first bounce is rho F Le), then the study's per-surface reference must lie within its own stated
 * error of it (plus the analytic form factors' tolerance). */
BN_TEST(plates_extrapolated_reference_within_its_error)
{
    const double g = 0.25, rho = 0.5;
    char args[1024], *out = NULL, line[64];
    double cont[2], first, Fpub, X = 1 / g;
    FILE *fp = fopen(bn_test_tmp("plates.obj"), "w");
    csv *c;
    fprintf(fp, "mtllib plates.mtl\nv 1 0 0\nv 0 0 0\nv 0 0 1\nv 1 0 1\nv 1 %g 0\nv 1 %g 1\nv 0 %g 1\nv 0 %g 0\n"
                "usemtl a\nf 1 2 3 4\nusemtl b\nf 5 6 7 8\n", g, g, g, g);
    fclose(fp);
    fp = fopen(bn_test_tmp("plates.mtl"), "w");
    fprintf(fp, "newmtl a\nKd %g %g %g\nKe 1 1 1\nnewmtl b\nKd %g %g %g\nKe 0 0 0\n", rho, rho, rho, rho, rho, rho);
    fclose(fp);
    plates_nystrom(g, rho, 32, cont, &first);
    /* Howell C-11, parallel equal squares of side a at gap c, X = Y = a / c */
    Fpub = 2 / (3.14159265358979323846 * X * X) *
           (0.5 * log((1 + X * X) * (1 + X * X) / (1 + 2 * X * X)) + 2 * X * sqrt(1 + X * X) * atan(X / sqrt(1 + X * X)) -
            2 * X * atan(X));
    BN_ASSERT_REL(first, rho * Fpub, 1e-9);
    snprintf(args, sizeof args, "study %s --vary patches=8,32,128 -o %s -q", bn_test_tmp("plates.obj"),
             bn_test_tmp("plates.csv"));
    if (bn_test_bounce(args, &out) != 0)
        BN_FAIL("bounce study failed:\n%s", out ? out : "");
    c = csv_read(bn_test_tmp("plates.csv"));
    for (int s = 0; s < 2; s++) {
        double e = meta_num(c, "reference_error"), ref;
        snprintf(line, sizeof line, "reference_mean_%c", "ab"[s]);
        ref = meta_num(c, line);
        fprintf(stderr, "surface %c: continuum %.9g, extrapolated reference %.9g (difference %.3g, stated error %.3g)\n",
                "ab"[s], cont[s], ref, fabs(ref - cont[s]) / cont[s], e);
        BN_ASSERT_LE(fabs(ref - cont[s]), (e + 5e-6) * cont[s]);   /* + the form factors' quadrature (~7e-7) */
    }
    BN_ASSERT_GT(meta_num(c, "reference_order"), 0.5);
    csv_free(c);
    free(out);
}

/* The report opens in a browser (headless Chromium from Debian) and shows what it claims: the
 * table with a row per setting and both plot panels, drawn (each panel an SVG with its axes' text),
 * with nothing fetched from elsewhere. Skipped, saying so, where no browser can be found. */
BN_TEST(report_opens_in_chromium)
{
    char args[2048], *out = NULL, *dom = NULL, *png;
    const char *browser = NULL, *cands[] = {"chromium", "chromium-browser", "google-chrome"};
    size_t npng = 0, rows = 0;
    for (int k = 0; k < 3 && !browser; k++) {
        snprintf(args, sizeof args, "command -v %s >/dev/null 2>&1", cands[k]);
        if (bn_test_run(args, NULL) == 0)
            browser = cands[k];
    }
    if (!browser)
        BN_SKIP("no browser: install Debian's chromium (scripts/setup.sh does) to run this test");
    snprintf(args, sizeof args, "study %s --patches 24 --ff hemisphere --vary bounces=0,1,2,3 --methods jacobi,direct "
                                "-o %s --report %s -q",
             bn_test_path("meshes/furnace-box.obj"), bn_test_tmp("r.csv"), bn_test_tmp("r.html"));
    if (bn_test_bounce(args, &out) != 0)
        BN_FAIL("bounce study failed:\n%s", out ? out : "");
    free(out);
    /* the page as the browser built it, and a picture of it; no network: every request refused */
    snprintf(args, sizeof args,
             "cd '%s' && timeout 120 %s --headless --no-sandbox --disable-gpu --disable-dev-shm-usage "
             "--host-resolver-rules='MAP * ~NOTFOUND' --window-size=1500,1400 --dump-dom 'file://%s' 2>/dev/null",
             bn_test_tmpdir(), browser, bn_test_tmp("r.html"));
    BN_ASSERT_EQ(bn_test_run(args, &dom), 0);
    BN_ASSERT(dom != NULL);
    BN_ASSERT(strstr(dom, "<table>") != NULL);
    for (const char *p = dom; (p = strstr(p, "<tr><td>")) != NULL; p++)
        rows++;
    BN_ASSERT_GE(rows, 4 + 2);   /* the truncated series at 0..3, and a row per method and tolerance */
    BN_ASSERT(strstr(dom, "id=\"panel0\"") && strstr(dom, "id=\"panel1\""));
    {
        const char *a = strstr(dom, "id=\"panel0\""), *b = strstr(dom, "id=\"panel1\"");
        BN_ASSERT(strstr(a, "<svg") && strstr(a, "<svg") < b);   /* each panel has its own drawing */
        BN_ASSERT(strstr(b, "<svg") != NULL);
    }
    BN_ASSERT(strstr(dom, "How it was made") && strstr(dom, "# command="));
    free(dom);
    snprintf(args, sizeof args,
             "cd '%s' && timeout 120 %s --headless --no-sandbox --disable-gpu --disable-dev-shm-usage "
             "--host-resolver-rules='MAP * ~NOTFOUND' --window-size=1500,1400 --screenshot='%s' 'file://%s' "
             ">/dev/null 2>&1",
             bn_test_tmpdir(), browser, bn_test_tmp("r.png"), bn_test_tmp("r.html"));
    BN_ASSERT_EQ(bn_test_run(args, NULL), 0);
    png = bn_test_read_file(bn_test_tmp("r.png"), &npng);
    BN_ASSERT(png && npng > 20000 && memcmp(png, "\x89PNG", 4) == 0);   /* a page with drawings, not a blank one */
    free(png);
}
