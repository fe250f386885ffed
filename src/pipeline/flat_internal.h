/* What the flat API's files share (src/pipeline/flat.c, flat_analysis.c): the handle behind bn_flat. Not installed. */
#ifndef BN_PIPELINE_FLAT_INTERNAL_H
#define BN_PIPELINE_FLAT_INTERNAL_H

#include "bounce/flat.h"
#include "bounce/pipeline.h"

#include <signal.h>

/* bn_flat_set: the images' and the bake's further options (src/pipeline/flat_more.c). */
typedef struct bn__flat_call {
    bn_bounces_opts bo;    /* light and gather samples, filter, emitter limits, tile, ev, crease; the rest per call */
    double up[3];          /* the camera's up direction, when has_up */
    int has_up;
    int gather_rays;       /* the bake's gather (bn_bake_gather_opts) */
    double bake_tol;
    int flat, no_colour_sets;   /* the bake: no shared vertices; no COLOR_n sets for the terms */
} bn__flat_call;
void bn__flat_call_default(bn__flat_call *c);

struct bn_flat {
    bn_pipeline p;
    bn_pipeline_opts po;   /* as loaded (bn_flat_load): the operator and solve stages use them */
    char transport[32];    /* the operator's name, once built */
    char transport_opt[16];   /* po.transport points here */
    int sigint;            /* catch SIGINT in later stages too (opts.sigint at load) */
    double *hist;          /* the monitor's rows, BN_FLAT_HISTORY values each */
    size_t nhist, caphist;
    void *op;   /* a caller's operator's context (bn_flat_solve_operator), freed after K */
    bn__flat_call call;    /* bn_flat_set */
    char two_sided[512];   /* po.load.two_sided points here (bn_flat_opts.more) */
};

/* SIGINT during a call (opts.sigint at load): the library's interrupt flag, which long loops poll. */
typedef struct bn__flat_sig {
    struct sigaction old;
    int on;
} bn__flat_sig;
void bn__flat_sig_begin(bn__flat_sig *s, int want);
void bn__flat_sig_end(bn__flat_sig *s);
/* f->po from the flat options (names checked; the transport's name kept in f). */
bn_status bn__flat_popts(const bn_flat_opts *o, bn_flat *f, char *msg, size_t msglen);
/* The camera of f's scene (its sidecar, else the default), then what is given (width, height, spp, fov
 * <= 0 and eye, look NULL keep it), validated; BN_EUSAGE/BN_EINPUT with the message in msg. */
bn_status bn__flat_camera(const bn_flat *f, int width, int height, int spp, const double *eye, const double *look,
                          double fov_deg, bn_camera *cam, char *msg, size_t msglen);
/* bn_flat_opts.more's `name=value` lines into po (solve_only: the solve's alone; the scene's are refused,
 * as a loaded scene keeps its F); the option names, per call, as bn_flat_names gives them. */
bn_status bn__flat_more_pipeline(const char *text, int solve_only, bn_flat *f, bn_pipeline_opts *po, char *msg,
                                 size_t msglen);
const char *bn__flat_scene_options(void);
const char *bn__flat_solve_options(void);
const char *bn__flat_image_options(void);
const char *bn__flat_bake_options(void);
/* text into msg (msglen bytes, may be 0); returns st. */
bn_status bn__flat_fail(bn_status st, const char *text, char *msg, size_t msglen);

#endif
