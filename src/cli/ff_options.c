/* The form-factor option group (shared by every subcommand that needs K). */
#include "cli/cli.h"

#include <string.h>

void bn_cli_hier_opts(const bn_cli_ff *ff, bn_hierarchy_opts *h)
{
    if (ff->eps >= 0)
        h->eps = ff->eps;
    h->clusters = !ff->no_clusters;
    h->flat_clusters = !ff->no_flat_clusters;
    h->volume_links = !ff->no_volume_links;
    h->normalize_rows = ff->normalize_rows;
    if (ff->link_samples > 0)
        h->samples = ff->link_samples;
    if (ff->min_area != 0)
        h->min_area = ff->min_area;
}

void bn_cli_add_ff(bn_optset *s, bn_cli_ff *o)
{
    o->eps = -1;
    bn_optset_add(s, (bn_opt){"transport", 0, BN_OPT_NAME, &o->transport, bn_pipeline_transports(), 0, 0,
                              bn_pipeline_transports(),
                              "how K is made: every pair's form factor kept dense or sparse, or hierarchical links "
                              "between clusters and elements; auto (default): hierarchical when dense F would not fit "
                              "or the scene has more than 6000 patches (--storage given: that storage); under mpirun -np P > 1 "
                              "hierarchical only (dense and sparse are single-process)"});
    bn_optset_add(s, (bn_opt){"eps", 0, BN_OPT_DOUBLE, &o->eps, NULL, 0, 1, "EPS",
                              "hierarchy: split a link while rho x B_source x F_bound exceeds EPS x the largest "
                              "emitted radiance (default 1e-3; 0: every link down to the patches)"});
    bn_optset_add(s, (bn_opt){"no-clusters", 0, BN_OPT_FLAG, &o->no_clusters, NULL, 0, 0, NULL,
                              "hierarchy: no volume clusters; start from every pair of input polygons"});
    bn_optset_add(s, (bn_opt){"no-flat-clusters", 0, BN_OPT_FLAG, &o->no_flat_clusters, NULL, 0, 0, NULL,
                              "hierarchy: clusters never receive as one node, only polygons' nodes do (default: "
                              "nearly flat clusters facing a source may, each polygon taking its cosine's share)"});
    bn_optset_add(s, (bn_opt){"no-volume-links", 0, BN_OPT_FLAG, &o->no_volume_links, NULL, 0, 0, NULL,
                              "hierarchy: a patch near a cluster (foliage) is not linked to it by its own hemisphere "
                              "rays; such pairs are split down to the patches (doc/hierarchy.md, \"Volume links\")"});
    bn_optset_add(s, (bn_opt){"normalize-rows", 0, BN_OPT_FLAG, &o->normalize_rows, NULL, 0, 0, NULL,
                              "hierarchy: scale each leaf's row of F to its exact sum, the share of its hemisphere "
                              "that reaches a surface (default: rows as the links make them; doc/hierarchy.md)"});
    bn_optset_add(s, (bn_opt){"link-samples", 0, BN_OPT_INT, &o->link_samples, NULL, 1, 1 << 16, "N",
                              "hierarchy: point pairs and rays per link above the patches (default 8; x4 when "
                              "partly visible and its noise could exceed eps/8)"});
    bn_optset_add(s, (bn_opt){"min-area", 0, BN_OPT_DOUBLE, &o->min_area, NULL, -1, 1e300, "A",
                              "hierarchy: planar elements smaller than A (scene units^2) are not split (default: "
                              "2^-20 of the scene's surface area; a negative value: down to the patches)"});
    bn_optset_add(s, (bn_opt){"ff", 0, BN_OPT_NAME, &o->method, bn_ff_method_names(), 0, 0,
                              "METHOD", "form factors: analytic (default), montecarlo or hemisphere"});
    bn_optset_add(s, (bn_opt){"samples", 0, BN_OPT_INT, &o->samples, NULL, 1, 1 << 24, "N",
                              "analytic: shadow rays per pair an occluder may block (default 32); montecarlo: "
                              "point pairs per pair (64); hemisphere: rays per patch (4096)"});
    bn_optset_add(s, (bn_opt){"precision", 0, BN_OPT_NAME, &o->precision, bn_cli_auto_or(bn_precision_names()), 0, 0,
                              bn_cli_auto_or(bn_precision_names()),
                              "storage precision of F (default auto: float, or double when float's rounding times "
                              "1/(1 - rho_max) would exceed --tol; sums are always double)"});
    bn_optset_add(s, (bn_opt){"storage", 0, BN_OPT_NAME, &o->storage, bn_storage_names(), 0, 0, bn_storage_names(),
                              "F storage: dense N^2 (default) or sparse CSR without the exact zeros"});
    bn_optset_add(s, (bn_opt){"sparse-threshold", 0, BN_OPT_DOUBLE, &o->sparse_threshold, NULL, 0, 0.999, "T",
                              "sparse: also drop F_ij < T; the dropped mass per row is reported (default 0)"});
    bn_optset_add(s, (bn_opt){"max-memory", 0, BN_OPT_SIZE, &o->max_memory, NULL, 1, 1e18, "BYTES",
                              "limit for F's storage (default 80% of physical memory)"});
    bn_optset_add(s, (bn_opt){"ff-tolerance", 0, BN_OPT_DOUBLE, &o->tolerance, NULL, 1e-12, 0.1, "T",
                              "analytic: relative tolerance per pair (default 1e-9; every pair by the closed form, whose cost hardly depends on it)"});
    bn_optset_add(s, (bn_opt){"ff-quadrature-only", 0, BN_OPT_FLAG, &o->quadrature_only, NULL, 0, 0, NULL,
                              "analytic: every pair by the point kernel's quadrature instead of the closed form (the path before it; for comparisons)"});
    bn_optset_add(s, (bn_opt){"ff-visibility", 0, BN_OPT_NAME, &o->visibility, bn_ff_visibility_names(), 0, 0,
                              bn_ff_visibility_names(),
                              "analytic, partly occluded pairs: exact (default), the visible part exactly at each "
                              "point of one patch, integrated (rows of closed scenes within 1e-4), or rays, 32 shadow "
                              "rays per pair (--samples; rows off by a few 1e-3, about a third of the time)"});
    bn_optset_add(s, (bn_opt){"cache", 0, BN_OPT_STRING, &o->cache, NULL, 0, 0, "FILE",
                              "reuse F from FILE when its key (scene, meshing, options) matches; else write it"});
}

void bn_cli_ff_opts(const bn_cli_ff *o, const bn_cli_common *c, bn_formfactor_opts *out)
{
    bn_formfactor_opts_default(out);
    if (o->method)
        bn_ff_method_parse(o->method, &out->method);   /* checked against the names when parsed */
    out->samples = o->samples;
    out->precision = BN_PRECISION_FLOAT;   /* auto starts from float */
    if (o->precision && strcmp(o->precision, "auto") != 0)
        bn_precision_parse(o->precision, &out->precision);   /* checked against the names when parsed */
    if (o->storage)
        out->storage = o->storage;
    out->sparse_threshold = o->sparse_threshold;
    out->max_memory = o->max_memory;
    if (o->tolerance > 0)
        out->tolerance = o->tolerance;
    out->quadrature_only = o->quadrature_only;
    if (o->visibility)
        bn_ff_visibility_parse(o->visibility, &out->exact_visibility);   /* checked when parsed */
    out->seed = c->seed;
    out->quiet = c->quiet;
    out->cache_path = o->cache;
    out->log.fn = bn_cli_log;
    out->log.user = (void *)c;
    out->log.quiet = c->quiet;
}

