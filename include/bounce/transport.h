/* bounce: the light-transport operator K = diag(rho) F behind one interface.
 *
 * Radiance vectors hold N patches x 3 channels interleaved: x[3*i + c], c = R, G, B. An operator
 * is a context pointer plus a table of functions (bn_transport_ops), each returning a status,
 * and a set of capabilities saying which of them it offers (PETSc's MatShell and
 * MatHasOperation, Embree's user geometry callbacks). The solvers ask for what they need:
 * every method needs y = F x; Gauss-Seidel needs rows; the direct solve needs entries. Dense and
 * sparse storage are two implementations; a user's own operator is a third, made with
 * bn_transport_create. K = diag(rho) F is applied by the wrapper: F is stored once, not per
 * channel, and every sum accumulates in double whatever the stored precision. */
#ifndef BOUNCE_TRANSPORT_H
#define BOUNCE_TRANSPORT_H

#include <stddef.h>
#include <stdint.h>
#include "bounce/status.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ---- the operator interface ---- */

/* What an operator can do beyond y = F x (which every operator offers). */
enum {
    BN_OP_ROWS = 1u << 0,     /* row: (F x)_i for one i (Gauss-Seidel) */
    BN_OP_ENTRIES = 1u << 1,  /* entry: F_ij; row_entries: the stored entries of row i (direct solve,
                                 diagnostics, files) */
    BN_OP_DIAG = 1u << 2      /* diag: F_ii for every i (Jacobi and Gauss-Seidel divide it out; without
                                 it they iterate L <- E + K L, whose fixed point is the same) */
};

/* The functions an operator provides. ctx is the operator's own state; err (may be NULL) takes
 * the message of a failure. An operator may return BN_EINTR/BN_ETERM (bn_interrupted()) from a
 * long apply; callers stop with that status and write nothing. */
struct bn_transport_links;
typedef struct bn_transport_ops {
    const char *name;   /* "dense-float", "csr-double", "sphere-test", ... (for logs and headers) */
    unsigned caps;      /* BN_OP_* bits of the optional functions below that are set */
    /* Required. y[3i+c] = sum_j F_ij x[3j+c] for every i and c; y does not alias x. Every value
     * must be finite: a non-finite one stops the caller with BN_ENUMERIC naming the call, patch and
     * channel. An operator spread over MPI ranks (the hierarchy's) may make apply a collective:
     * then every rank calls it alike (bounce's solvers do). */
    bn_status (*apply)(void *ctx, const double *x, double *y, bn_error *err);
    /* BN_OP_ROWS. out[c] = sum_j F_ij x[3j+c]. Called from one thread at a time per operator. */
    bn_status (*row)(void *ctx, size_t i, const double *x, double out[3], bn_error *err);
    /* BN_OP_ENTRIES. *v = F_ij. */
    bn_status (*entry)(void *ctx, size_t i, size_t j, double *v, bn_error *err);
    /* BN_OP_ENTRIES, optional even then (NULL: entry is asked for every column). The stored
     * entries of row i in increasing column order: cols and vals have room for N; *count is set.
     * Entries not returned are exactly 0. */
    bn_status (*row_entries)(void *ctx, size_t i, size_t *cols, double *vals, size_t *count, bn_error *err);
    /* BN_OP_DIAG. d[i] = F_ii, N values. */
    bn_status (*diag)(void *ctx, double *d, bn_error *err);
    /* Optional: bytes the operator holds (NULL: 0). */
    size_t (*bytes)(const void *ctx);
    /* Optional: releases ctx (NULL: nothing to release; the caller owns ctx). */
    void (*destroy)(void *ctx);
    /* Optional: F as links between the nodes of a tree (bn_transport_links; NULL: its entries, with
     * BN_OP_ENTRIES, one node per patch); count_only: only npatch, nnodes and nlinks set. */
    bn_status (*links)(const void *ctx, struct bn_transport_links *out, int count_only, bn_error *err);
} bn_transport_ops;

typedef struct bn_transport bn_transport;   /* opaque: ops + ctx + rho */

/* Makes K = diag(rho) F from an operator for F: n patches, rho (n*3 reflectances, each in [0, 1],
 * copied), ops (borrowed: must outlive the transport; usually a static table) and ctx (owned from
 * now on when ops->destroy is set: destroyed with the transport, or at once if this call fails).
 * Fails with BN_EINPUT for a reflectance outside [0, 1] and BN_EUSAGE for an ops table without
 * apply or with a capability whose function is missing. */
bn_status bn_transport_create(size_t n, const double *rho, const bn_transport_ops *ops, void *ctx,
                              bn_transport **out, bn_error *err);
void bn_transport_destroy(bn_transport *k);   /* NULL is a no-op */

size_t        bn_transport_size(const bn_transport *k);   /* N patches */
const double *bn_transport_rho(const bn_transport *k);    /* borrowed, N*3 */
/* New reflectances (N*3, copied; each in [0, 1], else BN_EINPUT naming the patch and nothing
 * changes): K = diag(rho) F for the same F, whatever keeps it (relighting needs no new F). */
bn_status     bn_transport_set_rho(bn_transport *k, const double *rho, bn_error *err);
const char   *bn_transport_name(const bn_transport *k);
unsigned      bn_transport_caps(const bn_transport *k);   /* BN_OP_* bits */
size_t        bn_transport_bytes(const bn_transport *k);  /* operator + rho */
/* The patch of the last non-finite value the operator handed out (the row of an entry), or
 * SIZE_MAX when it never did. */
size_t        bn_transport_nonfinite_patch(const bn_transport *k);

/* Asks for capabilities `need` on behalf of `who` (a solver's name): BN_OK, or BN_ENOTSUP with a
 * message naming what is missing and what would serve instead. */
bn_status bn_transport_require(const bn_transport *k, unsigned need, const char *who, bn_error *err);

/* y = K x: y[3i+c] = rho[3i+c] * sum_j F_ij x[3j+c]. x, y: N*3; y must not alias x. */
bn_status bn_transport_apply(const bn_transport *k, const double *x, double *y, bn_error *err);
/* y = F x (no reflectance). */
bn_status bn_transport_apply_F(const bn_transport *k, const double *x, double *y, bn_error *err);
/* out[c] = (K x)_i for channel c (needs BN_OP_ROWS). */
bn_status bn_transport_row(const bn_transport *k, size_t i, const double *x, double out[3], bn_error *err);
/* *v = F_ij (needs BN_OP_ENTRIES). */
bn_status bn_transport_entry(const bn_transport *k, size_t i, size_t j, double *v, bn_error *err);
/* The stored entries of row i of F (needs BN_OP_ENTRIES): cols, vals with room for N. */
bn_status bn_transport_row_entries(const bn_transport *k, size_t i, size_t *cols, double *vals, size_t *count,
                                   bn_error *err);
/* d[i] = F_ii (BN_OP_DIAG, else from entries; BN_ENOTSUP when the operator has neither). */
bn_status bn_transport_diag(const bn_transport *k, double *d, bn_error *err);
/* ||K||_inf per channel and overall: max_i rho_ic sum_j F_ij, F >= 0 (the contraction factor that
 * bounds the Neumann series), from K applied to ones. A row that is not finite or sums below 0 is
 * BN_ENUMERIC naming it (its patch in *bad_patch). per_channel and bad_patch may be NULL. */
bn_status bn_transport_norm_inf(const bn_transport *k, double *norm, double per_channel[3], size_t *bad_patch,
                                bn_error *err);
/* ---- F exported, for a program of its own that applies it (the live viewer page's worker) ----
 * Nodes of a binary tree above the patches: node v's children are child[v] and child[v] + 1 (BN_LINK_NONE:
 * a leaf, whose patch is leaf_patch[v]); children come after their parents. F x is
 *   pull: B_v = x[leaf_patch[v]] at a leaf, else the area-weighted mean of its two children's B;
 *   gather: G_r = sum of F[l] B_src[l] over r's links l in [start[r], start[r + 1]); a cluster receiver
 *     (cluster[r] 1) gathers per channel the vector sum F[l] B_src[l] u_l instead, u_l the unit direction
 *     dir[l] (octahedral: bn_transport_links_dir);
 *   push: top down, a planar node adds its parent's G; a cluster adds its parent cluster's vectors; a
 *     planar node under a cluster adds the dot product of its normal with its parent's vectors;
 *   (F x)_i = rowscale[i] (1 when NULL) times G at patch i's leaf.
 * Dense and sparse F: one leaf per patch (node i is patch i), a link per stored entry, no cluster. */
#define BN_LINK_NONE UINT32_MAX
typedef struct bn_transport_links {
    size_t npatch, nnodes, nlinks;
    uint32_t *child, *leaf_patch;   /* per node */
    uint8_t *cluster;               /* per node: 1 a volume cluster receiver */
    float *area;                    /* per node (scene units squared; only ratios matter) */
    float *normal;                  /* 3 per node (planar nodes under a cluster) */
    uint32_t *start;                /* nnodes + 1 */
    uint32_t *src;                  /* per link: the source node */
    float *F;                       /* per link */
    uint16_t *dir;                  /* per link: cluster receivers' direction to the source; NULL: none */
    float *rowscale;                /* npatch; NULL: none */
} bn_transport_links;
/* K's F as links (the operator's own, or its entries); BN_EUSAGE for an operator with neither, BN_ENOMEM
 * above 2^32 links. Free with bn_transport_links_free. */
bn_status bn_transport_links_get(const bn_transport *k, bn_transport_links *out, bn_error *err);
void bn_transport_links_free(bn_transport_links *l);
/* The links' bytes as bn_transport_links holds them (the page embeds the same), from their count alone
 * (no export): the operator's own count, or its stored entries counted row by row. */
bn_status bn_transport_links_bytes(const bn_transport *k, size_t *bytes, bn_error *err);
/* Link l's unit direction (cluster receivers): the octahedral decoding of dir[l], 8 bits per axis. */
void bn_transport_links_dir(uint16_t e, double u[3]);

/* F as a row-major N*N double array (needs BN_OP_ENTRIES; caller allocates N*N). */
bn_status bn_transport_to_dense(const bn_transport *k, double *F, bn_error *err);

/* ---- storage: how an assembled F is kept ----
 * An open set of named storages ("dense": N^2 values; "sparse": compressed rows without the exact
 * zeros), each in float or double. Code that computes F hands it to a builder and never learns how
 * it is kept; a new storage plugs in as one more table in src/transport (see storage.h there). */
typedef enum bn_precision { BN_PRECISION_FLOAT, BN_PRECISION_DOUBLE } bn_precision;
const char *bn_precision_name(bn_precision p);            /* "float", "double" */
const char *bn_precision_names(void);                     /* "float|double" */
int         bn_precision_parse(const char *s, bn_precision *out);   /* 0 on success */
/* Relative rounding of one stored value: 2^-24 (float), 2^-53 (double). */
double      bn_precision_epsilon(bn_precision p);
/* Bytes of one stored value (4, 8) and the significant digits that print it exactly (9, 17). */
unsigned    bn_precision_bytes(bn_precision p);
int         bn_precision_digits(bn_precision p);

#define BN_STORAGE_DEFAULT "dense"
/* The storage names, "|"-separated ("dense|sparse"), for help texts and choices. */
const char *bn_storage_names(void);
/* 1 if `name` is a storage. */
int bn_storage_exists(const char *name);
/* Does the storage need each row's column set before values arrive (a pattern)? */
int bn_storage_needs_pattern(const char *name);
/* Bytes the storage needs for n rows holding nnz entries (dense: nnz is ignored); SIZE_MAX on
 * overflow or an unknown name. */
size_t bn_storage_bytes(const char *name, size_t n, size_t nnz, bn_precision prec);
/* The options that keep F in less memory than `name` in `prec` (", --storage sparse, --precision
 * float"; empty when none), for messages that name remedies. */
void bn_storage_smaller(const char *name, bn_precision prec, char *buf, size_t size);

/* Row i's possible columns, in increasing order, written to cols (room for n) unless cols is NULL;
 * returns their count. Called from several threads at once, for distinct rows. */
typedef size_t (*bn_pattern_fn)(void *user, size_t i, uint32_t *cols);

typedef struct bn_builder_opts {
    const char  *storage;      /* a storage name (default BN_STORAGE_DEFAULT) */
    bn_precision precision;    /* default float */
    double       drop_below;   /* finish drops stored entries below it (storages that can; default 0:
                                  exact zeros only) */
    size_t       max_bytes;    /* refuse (BN_ENOMEM, *need set) above it; 0: no limit */
    bn_pattern_fn pattern;     /* the rows' column sets, for storages that need them (else unused) */
    void        *pattern_user;
} bn_builder_opts;
void bn_builder_opts_default(bn_builder_opts *o);

typedef struct bn_builder_report {
    size_t dropped_entries;    /* entries finish dropped (0 or below drop_below) */
    double dropped_mass_max;   /* largest per-row sum of what was dropped */
    size_t lost_puts;          /* puts outside the pattern (not stored) */
} bn_builder_report;

typedef struct bn_transport_builder bn_transport_builder;

/* Storage for F of n patches, zeroed. *need (may be NULL) receives the bytes it takes (counted
 * from the pattern where the storage needs one), also when it is refused for max_bytes. */
bn_status bn_transport_builder_create(size_t n, const bn_builder_opts *o, size_t *need, bn_transport_builder **out,
                                      bn_error *err);
/* F_ij = v. Thread-safe for distinct (i, j). Returns 0 when the storage has no place for (i, j)
 * (outside its pattern): the value is not stored, and the report counts it. */
int bn_transport_builder_put(bn_transport_builder *b, size_t i, size_t j, double v);
/* Row i at once: count values for columns cols[0..count) (increasing). */
bn_status bn_transport_builder_put_row(bn_transport_builder *b, size_t i, const size_t *cols, const double *vals,
                                       size_t count, bn_error *err);
/* Turns the filled storage into K = diag(rho) F (rho: n*3, copied) and frees the builder, also on
 * failure. rep may be NULL. */
bn_status bn_transport_builder_finish(bn_transport_builder *b, const double *rho, bn_transport **out,
                                      bn_builder_report *rep, bn_error *err);
void bn_transport_builder_destroy(bn_transport_builder *b);   /* abandons it; NULL is a no-op */

/* Convenience over the builder: F from a row-major N*N double array, stored as `storage` in
 * `prec` (sparse: exact zeros and entries below drop_below are not kept). Tests, generators. */
bn_status bn_transport_from_array(size_t n, const double *F, const double *rho, const char *storage,
                                  bn_precision prec, double drop_below, bn_transport **out, bn_error *err);

#ifdef __cplusplus
}
#endif
#endif
