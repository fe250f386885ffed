/* What the flat API's files share (src/pipeline/flat.c, flat_analysis.c): the handle behind bn_flat. Not installed. */
#ifndef BN_PIPELINE_FLAT_INTERNAL_H
#define BN_PIPELINE_FLAT_INTERNAL_H

#include "bounce/flat.h"
#include "bounce/pipeline.h"

#include <signal.h>

struct bn_flat {
    bn_pipeline p;
    bn_pipeline_opts po;   /* as loaded (bn_flat_load): the operator and solve stages use them */
    char transport[32];    /* the operator's name, once built */
    char transport_opt[16];   /* po.transport points here */
    int sigint;            /* catch SIGINT in later stages too (opts.sigint at load) */
    double *hist;          /* the monitor's rows, BN_FLAT_HISTORY values each */
    size_t nhist, caphist;
    void *op;   /* a caller's operator's context (bn_flat_solve_operator), freed after K */
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
/* text into msg (msglen bytes, may be 0); returns st. */
bn_status bn__flat_fail(bn_status st, const char *text, char *msg, size_t msglen);

#endif
