/* `bounce formfactors SCENE -o F.csv|F.bin`: F with visibility, its diagnostics, and the file. */
#include "cli/cli.h"
#include "base/internal.h"

#include <string.h>

/* F with its provenance lines (command, version, options, scene, the diagnostics) to output. */
static bn_status bn__ff_write_output(const bn_pipeline *p, const bn_pipeline_opts *po, const bn_cli_common *c,
                                     const char *output, bn_error *err)
{
    const bn_ff_diagnostics *d = &p->ff;
    char desc[512], *prov;
    size_t plen;
    bn_status st;
    bn_formfactor_opts_describe(&po->ff, desc, sizeof desc);
    plen = strlen(c->cmdline) + strlen(desc) + 512;
    prov = malloc(plen);
    if (!prov)
        return bn_error_set(err, BN_ENOMEM, "out of memory");
    snprintf(prov, plen,
             "# %s\n# bounce %s\n# %s\n# scene %s digest %016llx, %zu patches, unit %s\n"
             "# row sums min %.9g max %.9g; reciprocity residual %.3g; ||K||_inf %.9g\n",
             c->cmdline, bn_version(), desc, bn_scene_path(p->scene), bn_scene_digest(p->scene), d->n,
             bn_unit_name(bn_scene_unit(p->scene)), d->row_sum_min, d->row_sum_max, d->reciprocity_residual,
             d->k_norm_inf);
    st = bn_ff_write(p->k, p->scene, output, prov, po->ff.precision, err);
    free(prov);
    return st;
}

/* The options' checks: -o ends in .csv or .bin; every pair's F, so never the hierarchy (which keeps
 * links, not entries); auto is the storage asked (or the default). */
static bn_status bn__ff_check(const char *output, const bn_cli_ff *fo, bn_pipeline_opts *po, bn_error *err)
{
    if (output) {
        const char *dot = strrchr(output, '.');
        if (!dot || (strcmp(dot, ".csv") != 0 && strcmp(dot, ".bin") != 0))
            return bn_error_set(err, BN_EUSAGE, "-o %s: the output must end in .csv or .bin", output);
    }
    if (!strcmp(po->transport, "hierarchical"))
        return bn_error_set(err, BN_EUSAGE, "--transport hierarchical: the hierarchy keeps links between clusters and "
                                            "elements, not every F_ij; formfactors takes dense or sparse");
    if (!strcmp(po->transport, "auto"))
        po->transport = fo->storage ? fo->storage : BN_STORAGE_DEFAULT;
    return BN_OK;
}

int bn_cmd_formfactors(int argc, char **argv, bn_cli_common *c)
{
    bn_optset set;
    bn_cli_scene so;
    bn_cli_ff fo;
    const char *pos[1], *output = NULL;
    bn_error err;
    bn_pipeline_opts po;
    bn_pipeline p;
    bn_status st;
    int prc;

    memset(&set, 0, sizeof set);
    memset(&so, 0, sizeof so);
    memset(&fo, 0, sizeof fo);
    set.usage = "bounce formfactors SCENE [meshing options] [form-factor options] -o F.csv|F.bin";
    set.summary =
        "Computes the form factors F_ij (the share of the light leaving patch i that arrives at patch j,\n"
        "with visibility) for the meshed SCENE, prints the diagnostics (row sums, reciprocity, entries\n"
        "outside [0, 1], occlusion, rays, ||K||_inf, bytes, time) and writes F: .csv with provenance\n"
        "lines, a header `patch,area,F0,F1,...` and one row per patch, or .bin (BNFF, see doc/formfactors.md).\n"
        "An entry outside [0, 1] or not finite is an error (exit 5).";
    bn_cli_add_scene(&set, &so);
    bn_cli_add_ff(&set, &fo);
    bn_optset_add(&set, (bn_opt){"output", 'o', BN_OPT_STRING, &output, NULL, 0, 0, "FILE",
                                 "write F to FILE (.csv or .bin); without it only the diagnostics are printed"});
    bn_cli_add_common(&set, c);
    bn_error_clear(&err);
    if (!bn_cli_parse_scene_command(&set, argc, argv, pos, &prc))
        return prc;
    bn_cli_pipeline_opts(&so, &fo, NULL, c, &po);
    if (bn__ff_check(output, &fo, &po, &err) != BN_OK)
        return bn_cli_fail(&err);
    st = bn_pipeline_scene(pos[0], &po, &p, &err);
    if (st == BN_OK)
        st = bn_pipeline_operator(&po, &p, &err);
    if (st != BN_OK) {
        bn_cli_fail(&err);
        bn_pipeline_free(&p);
        return bn_status_exit_code(st);
    }
    if (!c->quiet)
        bn_ff_diagnostics_print(&p.ff, stdout);
    if (output) {
        st = bn__ff_write_output(&p, &po, c, output, &err);
        if (st != BN_OK)
            bn_cli_fail(&err);
        else if (!c->quiet)
            printf("wrote                %s\n", output);
    }
    bn_pipeline_free(&p);
    return bn_status_exit_code(st);
}
