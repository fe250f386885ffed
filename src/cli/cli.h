/* The `bounce` command: option tables, shared option groups, and the subcommands. */
#ifndef BOUNCE_CLI_H
#define BOUNCE_CLI_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include "bounce/scene.h"
#include "bounce/solve.h"

typedef enum bn_opt_type {
    BN_OPT_FLAG,     /* int, set to 1 */
    BN_OPT_INT,      /* int within [min, max] */
    BN_OPT_SIZE,     /* size_t within [min, max] */
    BN_OPT_U64,      /* uint64_t */
    BN_OPT_DOUBLE,   /* finite double within [min, max] */
    BN_OPT_STRING,   /* const char * */
    BN_OPT_CHOICE,   /* int: index of the value in `choices` ("a|b|c") */
    BN_OPT_NAME,     /* const char *: one of `choices` ("a|b|c", a library's vocabulary), kept as given */
    BN_OPT_VEC3,     /* double[3] from "x,y,z" */
    BN_OPT_WXH,      /* int[2] from "WxH" */
    BN_OPT_EDIT      /* bn_cli_edits: one more material edit, "NAME=R,G,B"; choices: "rho" or "Le";
                        may be given again (each appends) */
} bn_opt_type;

typedef struct bn_opt {
    const char *name;      /* long name without dashes */
    char        short_name;
    bn_opt_type type;
    void       *dest;
    const char *choices;   /* BN_OPT_CHOICE, BN_OPT_NAME: a library vocabulary's names() ("a|b|c"); a
                              CHOICE's index is then the enum's value (the library's tables are in
                              enum order: BN__VOCABULARY in base/internal.h) */
    double      min, max;  /* numeric range (inclusive) */
    const char *metavar;
    const char *help;      /* with the default, e.g. "(default 1e-6)" */
} bn_opt;

#define BN_CLI_MAX_OPTS 96
typedef struct bn_optset {
    bn_opt opt[BN_CLI_MAX_OPTS];
    size_t n;
    const char *usage;     /* "bounce info SCENE [options]" */
    const char *summary;   /* one paragraph */
    unsigned char seen[BN_CLI_MAX_OPTS];
} bn_optset;

void bn_optset_add(bn_optset *s, bn_opt o);
/* Parses argv[1..]; positional arguments are collected in order. --help sets *help to 1,
 * --version to 2 (the caller prints). Unknown options, missing or bad values are usage errors (exit 2) naming them. */
bn_status bn_cli_parse(bn_optset *s, int argc, char **argv, const char **positional, size_t max_positional,
                       size_t *npositional, int *help, bn_error *err);
void bn_cli_print_help(const bn_optset *s, FILE *fp);
/* The usual start of a subcommand taking one SCENE: parses, prints --help, checks that exactly one
 * positional argument was given (pos[0]). Returns 1 to go on; 0 with *rc the exit code to return. */
int bn_cli_parse_scene_command(bn_optset *s, int argc, char **argv, const char **pos, int *rc);
/* Was the option given on the command line? */
int bn_cli_given(const bn_optset *s, const char *name);

/* Options every subcommand takes. */
typedef struct bn_cli_common {
    int      threads;     /* 0 = all cores */
    uint64_t seed;
    int      quiet;
    int      no_summary;  /* set by a command that runs another (view bakes first): that one's progress
                             and notes, not its "wrote" line */
    const char *cmdline;  /* the full command line, for provenance */
} bn_cli_common;
void bn_cli_add_common(bn_optset *s, bn_cli_common *c);

/* Material edits given on the command line (--set-rho, --set-Le), in order. */
#define BN_CLI_MAX_EDITS 64
typedef struct bn_cli_edits {
    bn_material_edit e[BN_CLI_MAX_EDITS];
    size_t n;
} bn_cli_edits;

/* Scene loading and meshing options. */
typedef struct bn_cli_scene {
    int    unit;          /* index into "m|cm|mm" */
    double patch_size;
    size_t patches;
    size_t default_patches;   /* the command's own default for --patches (0: the library's, 1200) */
    int    no_subdivide;
    int    no_contacts;
    int    self_contacts;
    double contact_gap;
    double planar_tol;
    int    orient;         /* bn_orient */
    const char *two_sided; /* bn_load_opts.two_sided */
    bn_cli_edits edits;    /* bn_load_opts.edits */
} bn_cli_scene;
void bn_cli_add_scene(bn_optset *s, bn_cli_scene *o);
/* Loads and meshes (the pipeline's first stage; transport "auto": the mesh a default solve makes,
 * the hierarchy's for a large scene; NULL: the mesh options alone); prints the error and returns
 * its status on failure. */
bn_status bn_cli_load_scene(const char *path, const bn_cli_scene *o, const bn_cli_common *c, const char *transport,
                            bn_scene **out);
/* Log sink for library notes and warnings: warnings always, notes unless --quiet (user: the bn_cli_common). */
void bn_cli_log(void *user, const bn_message *m);
/* The same with notes on stdout without a prefix ("wrote FILE ..."), for commands whose notes are
 * their output. */
void bn_cli_stdout_log(void *user, const bn_message *m);

/* Prints "bounce: <message>" and returns the exit code of the status. */
int bn_cli_fail(const bn_error *err);
/* Returns the exit code for an interrupted run if one happened, else 0. */
int bn_cli_interrupted(void);

/* "auto|" and a vocabulary's names (for BN_OPT_NAME choices); the CLI's own static buffer. */
const char *bn_cli_auto_or(const char *names);
/* A solver method option: NULL or "auto" leave *method_auto 1; else the method. */
void bn_cli_method(const char *name, bn_solve_method *m, int *method_auto);

/* A library message with each backquoted option name (`max_iter`) written as its flag (--max-iter). */
const char *bn_cli_translate(const char *msg, char *out, size_t n);

/* The exit-code table, for --help. */
extern const char bn_cli_exit_codes[];

/* Form-factor options (src/cli/ff_options.c), shared by formfactors, solve, bounces, study. */
#include "bounce/formfactor.h"
typedef struct bn_cli_ff {
    const char *method;       /* one of bn_ff_method_names(); NULL = analytic */
    int    samples;           /* 0 = the method's default */
    const char *precision;    /* "auto" (or NULL) or one of bn_precision_names() */
    const char *storage;      /* a storage name (bn_storage_names()); NULL = the default */
    double sparse_threshold;
    size_t max_memory;        /* bytes, 0 = 80% of physical memory */
    double tolerance;         /* 0 = default */
    int    quadrature_only;
    const char *visibility;   /* one of bn_ff_visibility_names() (NULL: exact) */
    const char *cache;        /* NULL: no cache */
    const char *transport;    /* one of bn_pipeline_transports(); NULL = auto */
    double eps;               /* hierarchy: link tolerance (< 0: the default) */
    int    no_clusters;       /* hierarchy: start from every pair of polygons */
    int    no_flat_clusters;  /* hierarchy: only polygons' nodes receive */
    int    no_volume_links;   /* hierarchy: near pairs into clusters split to the patches */
    int    normalize_rows;    /* hierarchy: each leaf's row of F_H scaled to its exact sum */
    int    link_samples;      /* hierarchy: point pairs per link above the patches (0: default) */
    double min_area;          /* hierarchy: smallest element split (0: default; < 0: none) */
} bn_cli_ff;
void bn_cli_add_ff(bn_optset *s, bn_cli_ff *o);
/* Fills library options from the CLI groups. */
void bn_cli_ff_opts(const bn_cli_ff *o, const bn_cli_common *c, bn_formfactor_opts *out);

/* Camera options (src/cli/camera_options.c), shared by bounces and trace: defaults from the
 * scene's box, then its NAME.camera sidecar, then these flags. */
#include "bounce/image.h"
typedef struct bn_cli_camera {
    double eye[3], look[3], up[3], fov;
    int    size[2];
    int    spp;
} bn_cli_camera;
void bn_cli_add_camera(bn_optset *s, bn_cli_camera *o);
bn_status bn_cli_make_camera(const bn_optset *s, const bn_cli_camera *o, const char *scene_path, const bn_scene *scene,
                             const bn_cli_common *c, bn_camera *cam, bn_error *err);
/* Camera as one provenance line: "eye x,y,z look x,y,z up x,y,z fov F size WxH spp N". */
void bn_cli_camera_describe(const bn_camera *cam, char *buf, size_t n);

/* Solver options for the image and bake commands (src/cli/camera_options.c) and the helper
 * running the whole pipeline with the bounce terms kept. */
#include "bounce/solve.h"
#include "bounce/pipeline.h"
/* The hierarchy's options given (eps, clusters, link samples, min area) onto h. */
void bn_cli_hier_opts(const bn_cli_ff *ff, bn_hierarchy_opts *h);
typedef struct bn_cli_solution {
    const char *method;   /* "auto" or one of bn_solve_method_names(); NULL = auto */
    double tol;        /* 0 = default 1e-6 */
    size_t max_iter;   /* 0 = default */
} bn_cli_solution;
void bn_cli_add_solution(bn_optset *s, bn_cli_solution *o);
/* The pipeline's options from the CLI groups (ff and sol may be NULL: the library's defaults). */
void bn_cli_pipeline_opts(const bn_cli_scene *so, const bn_cli_ff *ff, const bn_cli_solution *sol,
                          const bn_cli_common *c, bn_pipeline_opts *out);
/* Provenance of a solve as `# key=value` lines (command, scene, unit, seed, form factors, the
 * hierarchy's figures) into buf; the solver's keys follow in bn_cli_patches_csv_write. */
void bn_cli_provenance_run(char *buf, size_t n, const bn_cli_common *c, const bn_pipeline_opts *po,
                           const bn_pipeline *p);
/* The per-patch CSV (atomic): prov, the solver's keys, then per patch L and, with_terms, every term
 * K^k E kept. */
bn_status bn_cli_patches_csv_write(const char *path, const char *prov, const bn_solve_opts *o, const bn_pipeline *p,
                                  int with_terms, bn_error *err);
/* The whole pipeline for `path` with the ray scene kept, solving (I - K) L = E keeping K^0 E ..
 * K^bounces E and rest; describe (may be NULL) receives the solver line for provenance. Prints
 * errors; returns the status. *p is the caller's to free, also on failure. */
bn_status bn_cli_run_solution(const char *path, const bn_cli_scene *so, const bn_cli_ff *ff,
                              const bn_cli_solution *sol, const bn_cli_common *c, int bounces, bn_pipeline *p,
                              char *describe, size_t ndescribe);

/* Subcommands: each takes argv from the subcommand's name on. */
int bn_cmd_info(int argc, char **argv, bn_cli_common *c);
int bn_cmd_view(int argc, char **argv, bn_cli_common *c);
int bn_cmd_view_live(int argc, char **argv, bn_cli_common *c);   /* view --live */
int bn_cmd_formfactors(int argc, char **argv, bn_cli_common *c);
int bn_cmd_solve(int argc, char **argv, bn_cli_common *c);
int bn_cmd_bounces(int argc, char **argv, bn_cli_common *c);
int bn_cmd_bake(int argc, char **argv, bn_cli_common *c);
int bn_cmd_trace(int argc, char **argv, bn_cli_common *c);
int bn_cmd_crosscheck(int argc, char **argv, bn_cli_common *c);
int bn_cmd_study(int argc, char **argv, bn_cli_common *c);

#endif
