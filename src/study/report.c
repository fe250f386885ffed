/* The study as one self-contained HTML page: how it was made, the table, the two plot panels
 * inline (SVG). Opens in any browser with nothing beside it. */
#include "study/study_internal.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>

static void bn__html(FILE *fp, const char *s)
{
    for (; s && *s; s++) {
        if (*s == '<')
            fputs("&lt;", fp);
        else if (*s == '>')
            fputs("&gt;", fp);
        else if (*s == '&')
            fputs("&amp;", fp);
        else if (*s == '"')
            fputs("&quot;", fp);
        else
            fputc(*s, fp);
    }
}

static void bn__cell(FILE *fp, double v)
{
    if (isnan(v))
        fputs("<td>-</td>", fp);
    else
        fprintf(fp, "<td>%.4g</td>", v);
}

/* How the study was made: the provenance lines, the reference, its error, the fitted order. */
static void bn__report_how(FILE *fp, const bn_study_result *r, const char *provenance)
{
    fputs("<h2>How it was made</h2>\n<dl>\n", fp);
    fputs("<dt>reference</dt><dd>", fp);
    bn__html(fp, r->reference);
    fprintf(fp, " (%zu patches, %.3g s)</dd>\n<dt>its error</dt><dd>%.3g per surface, %.3g per patch: ", r->ref_patches,
            r->ref_seconds, r->ref_error, r->ref_error_patch);
    bn__html(fp, r->ref_error_how);
    fputs("</dd>\n", fp);
    if (isfinite(r->ref_order))
        fprintf(fp, "<dt>convergence order (Richardson, from the reference's levels)</dt><dd>%.3g</dd>\n", r->ref_order);
    fputs("</dl>\n<pre class=\"provenance\">", fp);
    bn__html(fp, provenance);
    fputs("</pre>\n", fp);
}

static void bn__report_table(FILE *fp, const bn_study_result *r)
{
    fputs("<h2>Settings</h2>\n<table>\n<tr><th>method</th><th>value</th><th>patches</th><th>iterations</th>"
          "<th>per surface (max)</th><th>per patch (max)</th><th>per patch (L1)</th><th>per patch (RMS)</th>"
          "<th>reflected power</th><th>bound</th><th>t_total (s)</th><th>peak (MiB)</th></tr>\n", fp);
    for (size_t i = 0; i < r->nrows; i++) {
        const bn_study_row *w = &r->rows[i];
        fputs("<tr><td>", fp);
        bn__html(fp, w->method);
        fputs("</td><td>", fp);
        bn__html(fp, w->value);
        fprintf(fp, "</td><td>%zu</td>", w->patches);
        if (w->iterations == SIZE_MAX)
            fputs("<td>-</td>", fp);
        else
            fprintf(fp, "<td>%zu</td>", w->iterations);
        bn__cell(fp, w->err_surface_max);
        bn__cell(fp, w->err_max_rel);
        bn__cell(fp, w->err_l1_rel);
        bn__cell(fp, w->err_rms_rel);
        bn__cell(fp, w->err_energy_rel);
        bn__cell(fp, w->bound);
        bn__cell(fp, w->t_total);
        bn__cell(fp, w->peak_mb);
        fputs("</tr>\n", fp);
    }
    fputs("</table>\n<p class=\"note\">Errors are relative: per patch and channel |L - L_ref| / max(|L_ref|, the "
          "scene's mean radiance); per surface the area-weighted mean's; doc/study.md gives each formula.</p>\n",
          fp);
}

bn_status bn_study_write_report(const bn_study_result *r, const char *path, const char *provenance,
                                const char *title, bn_error *err)
{
    char *svg[2] = {NULL, NULL};
    bn__outfile f;
    bn_status st = BN_OK;
    for (int k = 0; k < 2 && st == BN_OK; k++)
        st = bn__study_panel_svg(r, k, path, &svg[k], err);
    if (st == BN_OK)
        st = bn__outfile_open(&f, path, "w", err);
    if (st == BN_OK) {
        FILE *fp = f.fp;
        fputs("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>bounce study: ", fp);
        bn__html(fp, bn_study_param_name(r->param));
        fputs("</title>\n<style>body{font-family:sans-serif;margin:2em;max-width:1500px}"
              "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}"
              "th{background:#eee}.plots{display:flex;flex-wrap:wrap;gap:1em}.plots figure{margin:0}.plots svg{width:620px;height:auto}"
              "pre{background:#f6f6f6;padding:0.6em;white-space:pre-wrap}.note{color:#555}</style>\n</head><body>\n", fp);
        fputs("<h1>bounce study: ", fp);
        bn__html(fp, bn_study_param_name(r->param));
        if (title && *title) {
            fputs(" &mdash; ", fp);
            bn__html(fp, title);
        }
        fputs("</h1>\n<h2>Plots</h2>\n<div class=\"plots\">\n", fp);
        for (int k = 0; k < 2; k++) {
            const char *s = strstr(svg[k], "<svg");   /* inline: the document's own prolog is dropped */
            fprintf(fp, "<figure id=\"panel%d\">%s</figure>\n", k, s ? s : "");
        }
        fputs("</div>\n", fp);
        bn__report_table(fp, r);
        bn__report_how(fp, r, provenance);
        fputs("</body></html>\n", fp);
        st = bn__outfile_commit(&f, err);
    }
    free(svg[0]);
    free(svg[1]);
    return st;
}
