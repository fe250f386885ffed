/* The per-pixel race (issue 35): `bounce bounces` with its defaults on the Cornell box at WxW against
 * a path-traced reference of at least 64k samples per pixel made once and kept with the bench
 * (bench/data/README.md says how), timed as a user runs it (the whole process: loading, form factors,
 * solve, gather, the EXR written), and its median per-pixel error in luminance with the reference's
 * own variance taken out: per pixel err^2 = max(0, (x - ref)^2 - var_ref), over the pixels whose
 * reference exceeds 1e-3 of the brightest. The reference's channels are read from its EXR (L and
 * L_var, as `bounce trace` writes them) through the OpenEXR C API.
 *
 * usage: race_bench BOUNCE REF.exr [--scene OBJ] [--runs N] [--target E] [-- extra bounces options] */
#include <openexr.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#ifndef BN_SOURCE_DIR
#define BN_SOURCE_DIR "."
#endif

static const double WY[3] = {0.2126, 0.7152, 0.0722};

typedef struct img {
    int w, h;
    float *L, *var;   /* 3wh each (var NULL when absent) */
} img;

/* Channel `layer.C` of an EXR into out (w*h floats, C in R, G, B); 0 when absent. */
static int read_layer(const char *path, const char *layer, img *im, float *out3)
{
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    const exr_attr_chlist_t *chl;
    exr_attr_box2i_t dw;
    int32_t lines;
    int found = 0;
    if (exr_start_read(&ctx, path, &init) != EXR_ERR_SUCCESS)
        return 0;
    exr_get_channels(ctx, 0, &chl);
    exr_get_data_window(ctx, 0, &dw);
    exr_get_scanlines_per_chunk(ctx, 0, &lines);
    im->w = dw.max.x - dw.min.x + 1;
    im->h = dw.max.y - dw.min.y + 1;
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    for (int y = 0; y < im->h; y += lines) {
        exr_chunk_info_t ci;
        if (exr_read_scanline_chunk_info(ctx, 0, y + dw.min.y, &ci) != EXR_ERR_SUCCESS)
            break;
        if (y == 0 ? exr_decoding_initialize(ctx, 0, &ci, &dec) : exr_decoding_update(ctx, 0, &ci, &dec))
            break;
        for (int c = 0; c < dec.channel_count; c++) {
            const char *name = dec.channels[c].channel_name, *dot = strrchr(name, '.');
            int k = dot ? (int)(strchr("RGB", dot[1]) ? strchr("RGB", dot[1]) - "RGB" : -1) : -1;
            dec.channels[c].decode_to_ptr = NULL;
            if (!dot || k < 0 || dot[2] || (size_t)(dot - name) != strlen(layer) || strncmp(name, layer, strlen(layer)))
                continue;
            found |= 1 << k;
            dec.channels[c].decode_to_ptr = (uint8_t *)(out3 + 3 * (size_t)(ci.start_y - dw.min.y) * im->w + k);
            dec.channels[c].user_pixel_stride = 12;
            dec.channels[c].user_line_stride = 12 * im->w;
            dec.channels[c].user_data_type = EXR_PIXEL_FLOAT;
            dec.channels[c].user_bytes_per_element = 4;
        }
        if (y == 0 && exr_decoding_choose_default_routines(ctx, 0, &dec) != EXR_ERR_SUCCESS)
            break;
        if (exr_decoding_run(ctx, 0, &dec) != EXR_ERR_SUCCESS)
            break;
    }
    exr_decoding_destroy(ctx, &dec);
    exr_finish(&ctx);
    return found == 7;
}

static int load(const char *path, img *im, int with_var)
{
    img probe = {0};
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    exr_attr_box2i_t dw;
    if (exr_start_read(&ctx, path, &init) != EXR_ERR_SUCCESS)
        return 0;
    exr_get_data_window(ctx, 0, &dw);
    exr_finish(&ctx);
    probe.w = dw.max.x - dw.min.x + 1;
    probe.h = dw.max.y - dw.min.y + 1;
    *im = probe;
    im->L = calloc((size_t)3 * probe.w * probe.h, sizeof(float));
    im->var = with_var ? calloc((size_t)3 * probe.w * probe.h, sizeof(float)) : NULL;
    return read_layer(path, "L", im, im->L) && (!with_var || read_layer(path, "L_var", im, im->var));
}

static int cmp_d(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* The median relative error (noise-corrected), raw, and the reference's own median standard error. */
static void median_err(const img *ref, const float *L, double out[3])
{
    size_t n = (size_t)ref->w * ref->h, m = 0;
    double *e = malloc(3 * n * sizeof *e), ymax = 0;
    for (size_t i = 0; i < n; i++)
        ymax = fmax(ymax, WY[0] * ref->L[3 * i] + WY[1] * ref->L[3 * i + 1] + WY[2] * ref->L[3 * i + 2]);
    for (size_t i = 0; i < n; i++) {
        double y = 0, x = 0, v = 0, d;
        for (int c = 0; c < 3; c++) {
            y += WY[c] * ref->L[3 * i + c];
            x += WY[c] * L[3 * i + c];
            v += WY[c] * WY[c] * ref->var[3 * i + c];
        }
        if (!(y > 1e-3 * ymax))
            continue;
        d = x - y;
        e[m] = sqrt(fmax(0, d * d - v)) / y;
        e[n + m] = fabs(d) / y;
        e[2 * n + m] = sqrt(v) / y;
        m++;
    }
    for (int k = 0; k < 3; k++) {
        qsort(e + k * n, m, sizeof *e, cmp_d);
        out[k] = m ? e[k * n + m / 2] : NAN;
    }
    free(e);
}

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

int main(int argc, char **argv)
{
    const char *scene = BN_SOURCE_DIR "/meshes/cornell-box.obj", *extra = "";
    int runs = 3;
    double target = 0.005, best = INFINITY, e[3];
    img ref, out;
    char cmd[8192], tmp[] = "/tmp/race_bench.XXXXXX";
    if (argc < 3) {
        fprintf(stderr, "usage: race_bench BOUNCE REF.exr [--scene OBJ] [--runs N] [--target E] [-- bounces options]\n");
        return 2;
    }
    for (int i = 3; i < argc; i++) {
        if (!strcmp(argv[i], "--scene") && i + 1 < argc)
            scene = argv[++i];
        else if (!strcmp(argv[i], "--runs") && i + 1 < argc)
            runs = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--target") && i + 1 < argc)
            target = atof(argv[++i]);
        else if (!strcmp(argv[i], "--") && i + 1 < argc) {
            extra = argv[i + 1];
            break;
        }
    }
    if (!load(argv[2], &ref, 1)) {
        fprintf(stderr, "race_bench: %s: no L and L_var layers (a `bounce trace` EXR)\n", argv[2]);
        return 1;
    }
    if (!mkdtemp(tmp))
        return 1;
    for (int r = 0; r < runs; r++) {
        double t0 = now();
        snprintf(cmd, sizeof cmd, "%s bounces %s --unit mm --size %dx%d --no-previews -q -o %s/race.exr %s", argv[1],
                 scene, ref.w, ref.h, tmp, extra);
        if (system(cmd) != 0) {
            fprintf(stderr, "race_bench: failed: %s\n", cmd);
            return 1;
        }
        best = fmin(best, now() - t0);
    }
    snprintf(cmd, sizeof cmd, "%s/race.exr", tmp);
    if (!load(cmd, &out, 0) || out.w != ref.w || out.h != ref.h) {
        fprintf(stderr, "race_bench: %s: unreadable or not %dx%d\n", cmd, ref.w, ref.h);
        return 1;
    }
    remove(cmd);
    rmdir(tmp);
    median_err(&ref, out.L, e);
    printf("| `bounce bounces` (defaults%s%s), %dx%d | %.2f | %.2f%% | %.2f%% | %.2f%% | %s |\n", *extra ? ": " : "",
           extra, ref.w, ref.h, best, 100 * e[0], 100 * e[1], 100 * e[2],
           e[0] <= target && best <= 6 ? "met" : "not met");
    free(ref.L);
    free(ref.var);
    free(out.L);
    return 0;
}
