/* Pinhole cameras: defaults from the scene's bounds, NAME.camera sidecars, primary rays. */
#include "bounce/image.h"
#include "base/internal.h"
#include "base/vec.h"
#include "image/image_internal.h"

#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <string.h>

void bn_camera_default(const bn_scene *s, bn_camera *cam)
{
    double lo[3], hi[3], c[3], half_h, half_w, dist;
    memset(cam, 0, sizeof *cam);
    cam->fov_deg = 40;
    cam->width = cam->height = 512;
    cam->spp = 1;
    cam->up[1] = 1;
    bn_scene_bounds(s, lo, hi);
    for (int k = 0; k < 3; k++)
        c[k] = 0.5 * (lo[k] + hi[k]);
    /* Fit the front face of the box (x, y extents) into the view from in front of it. */
    half_w = 0.5 * (hi[0] - lo[0]);
    half_h = 0.5 * (hi[1] - lo[1]);
    dist = fmax(half_h, half_w) / tan(0.5 * cam->fov_deg * BN_PI / 180.0) * 1.05;
    if (!(dist > 0))
        dist = 1;
    memcpy(cam->look, c, sizeof c);
    memcpy(cam->eye, c, sizeof c);
    cam->eye[2] = lo[2] - dist;
    double aspect;
    const char *name;
    if (bn_scene_camera(s, cam->eye, cam->look, cam->up, &cam->fov_deg, &aspect, &name) && aspect > 0) {
        /* the file's camera (glTF): its pose and field of view, its aspect at 512 pixels wide */
        int h = (int)lround(512 / aspect);
        cam->height = h < 1 ? 1 : h > 32768 ? 32768 : h;
    }
}

bn_status bn_camera_validate(const bn_camera *cam, bn_error *err)
{
    double f[3], r[3];
    for (int k = 0; k < 3; k++)
        if (!isfinite(cam->eye[k]) || !isfinite(cam->look[k]) || !isfinite(cam->up[k]))
            return bn_error_set(err, BN_EINPUT, "camera: eye, look and up must be finite");
    bn_v3_sub(cam->look, cam->eye, f);
    if (bn_v3_normalize(f) <= 0)
        return bn_error_set(err, BN_EINPUT, "camera: eye and look are the same point (%g,%g,%g)", cam->eye[0],
                            cam->eye[1], cam->eye[2]);
    bn_v3_cross(f, cam->up, r);
    if (!(bn_v3_len(r) > 1e-9 * bn_v3_len(cam->up)) || bn_v3_len(cam->up) == 0)
        return bn_error_set(err, BN_EINPUT, "camera: up (%g,%g,%g) is zero or parallel to the view direction",
                            cam->up[0], cam->up[1], cam->up[2]);
    if (!(cam->fov_deg > 0 && cam->fov_deg < 180))
        return bn_error_set(err, BN_EINPUT, "camera: fov %g is not in (0, 180) degrees", cam->fov_deg);
    if (cam->width < 1 || cam->height < 1 || cam->width > 32768 || cam->height > 32768)
        return bn_error_set(err, BN_EINPUT, "camera: size %dx%d is not within 1..32768", cam->width, cam->height);
    if (cam->spp < 1 || cam->spp > 65536)
        return bn_error_set(err, BN_EINPUT, "camera: spp %d is not within 1..65536", cam->spp);
    return BN_OK;
}

void bn_camera_ray(const bn_camera *cam, double x, double y, double org[3], double dir[3])
{
    double f[3], r[3], u[3], th = tan(0.5 * cam->fov_deg * BN_PI / 180.0);
    double aspect = (double)cam->width / cam->height;
    double sx = (2 * x / cam->width - 1) * th * aspect, sy = (1 - 2 * y / cam->height) * th;
    bn_v3_sub(cam->look, cam->eye, f);
    bn_v3_normalize(f);
    bn_v3_cross(f, cam->up, r);   /* image right = forward x up */
    bn_v3_normalize(r);
    bn_v3_cross(r, f, u);         /* true up, orthogonal to both */
    for (int k = 0; k < 3; k++) {
        org[k] = cam->eye[k];
        dir[k] = f[k] + sx * r[k] + sy * u[k];
    }
    bn_v3_normalize(dir);
}

static int bn__parse_vec3(const char *v, double out[3])
{
    char *end;
    for (int k = 0; k < 3; k++) {
        errno = 0;
        out[k] = strtod(v, &end);
        if (end == v || errno || !isfinite(out[k]))
            return 0;
        v = end;
        while (isspace((unsigned char)*v))
            v++;
        if (k < 2) {
            if (*v != ',')
                return 0;
            v++;
        }
    }
    return *v == '\0';
}

/* One sidecar line (comments and blanks already stripped): KEY VALUE into *c. */
static bn_status bn__camera_line(char *p, const char *path, unsigned ln, bn_camera *c, bn_error *err)
{
    char *key = p, *val, *end;
    while (*p && !isspace((unsigned char)*p))
        p++;
    if (*p)
        *p++ = '\0';
    while (isspace((unsigned char)*p))
        p++;
    val = p;
    if (strcmp(key, "eye") == 0 || strcmp(key, "look") == 0 || strcmp(key, "up") == 0) {
        double *d = key[0] == 'e' ? c->eye : key[0] == 'l' ? c->look : c->up;
        if (!bn__parse_vec3(val, d))
            return bn_error_set(err, BN_EINPUT, "%s:%u: %s '%s' is not three finite numbers X,Y,Z", path, ln, key, val);
    } else if (strcmp(key, "fov") == 0) {
        c->fov_deg = strtod(val, &end);
        if (end == val || *end || !(c->fov_deg > 0 && c->fov_deg < 180))
            return bn_error_set(err, BN_EINPUT, "%s:%u: fov '%s' is not an angle in (0, 180) degrees", path, ln, val);
    } else if (strcmp(key, "size") == 0) {
        long w = strtol(val, &end, 10), h = 0;
        if (end != val && *end == 'x') {
            char *b = end + 1;
            h = strtol(b, &end, 10);
            if (end == b)
                h = 0;
        }
        if (*end || w < 1 || h < 1 || w > 32768 || h > 32768)
            return bn_error_set(err, BN_EINPUT, "%s:%u: size '%s' is not WIDTHxHEIGHT within 1..32768", path, ln, val);
        c->width = (int)w;
        c->height = (int)h;
    } else if (strcmp(key, "spp") == 0) {
        long n = strtol(val, &end, 10);
        if (end == val || *end || n < 1 || n > 65536)
            return bn_error_set(err, BN_EINPUT, "%s:%u: spp '%s' is not a whole number within 1..65536", path, ln, val);
        c->spp = (int)n;
    } else {
        return bn_error_set(err, BN_EINPUT, "%s:%u: unknown key '%s' (keys: eye, look, up, fov, size, spp)", path, ln,
                            key);
    }
    return BN_OK;
}

bn_status bn__camera_parse(FILE *fp, const char *path, bn_camera *cam, bn_error *err)
{
    char line[1024];
    unsigned ln = 0;
    bn_camera c = *cam;
    bn_status st = BN_OK;
    while (st == BN_OK && fgets(line, sizeof line, fp)) {
        char *p = line, *e;
        ln++;
        if (!strchr(line, '\n') && !feof(fp))
            return bn_error_set(err, BN_EINPUT, "%s:%u: line too long", path, ln);
        if ((e = strchr(p, '#')))
            *e = '\0';
        while (isspace((unsigned char)*p))
            p++;
        e = p + strlen(p);
        while (e > p && isspace((unsigned char)e[-1]))
            *--e = '\0';
        if (*p)
            st = bn__camera_line(p, path, ln, &c, err);
    }
    if (st == BN_OK && ferror(fp))
        st = bn_error_set(err, BN_EIO, "%s: read error", path);
    if (st == BN_OK)
        *cam = c;
    return st;
}

bn_status bn_camera_load_sidecar(const char *scene_path, bn_camera *cam, int *found, bn_error *err)
{
    const char *slash = strrchr(scene_path, '/'), *dot = strrchr(scene_path, '.');
    size_t stem = (dot && (!slash || dot > slash)) ? (size_t)(dot - scene_path) : strlen(scene_path);
    char *path = malloc(stem + 8);
    FILE *fp;
    bn_status st;
    if (found)
        *found = 0;
    if (!path)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    memcpy(path, scene_path, stem);
    strcpy(path + stem, ".camera");
    fp = fopen(path, "r");
    if (!fp) {
        int e = errno;
        st = e == ENOENT ? BN_OK : bn_error_set(err, BN_EIO, "%s: cannot read: %s", path, strerror(e));
        free(path);
        return st;
    }
    st = bn__camera_parse(fp, path, cam, err);
    fclose(fp);
    if (st == BN_OK && found)
        *found = 1;
    free(path);
    return st;
}
