/* Study plots through PLplot's C API: two panels (error against time, error against the varied
 * parameter), written as PNG (pngcairo) and SVG, each to a temporary name renamed into place.
 * Colours are set explicitly (PLplot's default palette is white on black) and the device is always
 * named, so PLplot never prompts for one. */
#include "study/study_internal.h"
#include "base/internal.h"

#include <math.h>
#include <string.h>
#include <plplot/plplot.h>

#define BN__MAXSER 16
#define BN__MAXPTS 4096

typedef struct bn__series {
    char label[64];
    int n;
    double x[BN__MAXPTS], y[BN__MAXPTS];   /* data units (logs taken when drawn) */
    int color, style, symbol;              /* symbol: 0 none */
    int vline;                             /* draw x[0] as a vertical line across the panel */
    int band;                              /* shade from the panel's bottom up to y over the x range */
} bn__series;

typedef struct bn__panel {
    char xlab[96], ylab[96], title[128];
    int xlog, ylog;
    int nser;
    bn__series ser[BN__MAXSER];
    char notes[8][48];   /* text beside points (categorical axes) */
    double nx[8], ny[8];
    int nnotes;
    int legend_low;      /* legend at the bottom left (error falling with time leaves it free) */
} bn__panel;

/* One colour per method in both panels; other series by position. */
#define BN__BAND_COLOR 10

/* One marker shape per series of a panel, so series stay apart in grey print too. */
static const char *bn__glyph(int index)
{
    static const char *const g[] = {"\u25CF", "\u25A0", "\u25B2", "\u25C6", "\u25BC", "\u2605", "\u25D0", "\u2B22"};
    return g[index % 8];
}

static int bn__color(const char *label, int index)
{
    static const char *const names[] = {"jacobi", "gauss-seidel", "neumann", "direct", "truncated", "radiosity", "trace"};
    for (int i = 0; i < 7; i++)
        if (strncmp(label, names[i], strlen(names[i])) == 0)
            return 2 + i;
    return 2 + index % 8;
}

static bn__series *bn__add(bn__panel *p, const char *label, int style, int symbol)
{
    bn__series *s;
    if (p->nser >= BN__MAXSER)
        return NULL;
    s = &p->ser[p->nser];
    memset(s, 0, sizeof *s);
    snprintf(s->label, sizeof s->label, "%s", label);
    s->color = bn__color(label, p->nser);
    s->style = style;
    s->symbol = symbol;
    p->nser++;
    return s;
}

static void bn__pt(bn__series *s, double x, double y)
{
    if (s && s->n < BN__MAXPTS && isfinite(x) && isfinite(y)) {
        s->x[s->n] = x;
        s->y[s->n] = y;
        s->n++;
    }
}

/* Log-axis labels every `step` decades (PLplot labels every decade on its own, which overlaps on
 * wide ranges). The callback receives the exponent. */
typedef struct bn__labstep { int x, y; } bn__labstep;
static void bn__label(PLINT axis, PLFLT v, char *out, PLINT n, PLPointer data)
{
    const bn__labstep *st = data;
    int step = axis == PL_X_AXIS ? st->x : st->y, e = (int)lround(v);
    if (step > 1 && e % step != 0)
        out[0] = '\0';
    else
        snprintf(out, (size_t)n, "10#u%d#d", e);
}

static double bn__tr(double v, int lg) { return lg ? log10(v) : v; }
static int bn__ok(double v, int lg) { return isfinite(v) && (!lg || v > 0); }

/* The window: the data's range (log10 on log axes), log axes at least 1.2 decades, 5% margins and
 * room for the legend above (or below) the data. r: x0, x1, y0, y1. */
static void bn__ranges(const bn__panel *p, double r[4])
{
    double x0 = INFINITY, x1 = -INFINITY, y0 = INFINITY, y1 = -INFINITY, dx, dy, room = 0;
    for (int i = 0; i < p->nser; i++)
        for (int k = 0; k < p->ser[i].n; k++) {
            double x = p->ser[i].x[k], y = p->ser[i].y[k];
            if (!bn__ok(x, p->xlog) || !bn__ok(y, p->ylog))
                continue;
            x0 = fmin(x0, bn__tr(x, p->xlog));
            x1 = fmax(x1, bn__tr(x, p->xlog));
            if (p->ser[i].vline)
                continue;
            y0 = fmin(y0, bn__tr(y, p->ylog));
            y1 = fmax(y1, bn__tr(y, p->ylog));
        }
    if (!(x0 <= x1)) {
        x0 = 0;
        x1 = 1;
    }
    if (!(y0 <= y1)) {
        y0 = 0;
        y1 = 1;
    }
    /* log axes span at least 1.2 decades, so a labelled decade always shows */
    if (p->xlog && x1 - x0 < 1.2) {
        double c = 0.5 * (x0 + x1);
        x0 = c - 0.6;
        x1 = c + 0.6;
    }
    if (p->ylog && y1 - y0 < 1.2) {
        double c = 0.5 * (y0 + y1);
        y0 = c - 0.6;
        y1 = c + 0.6;
    }
    /* margins: 5% (at least a unit's share when the range is flat) */
    dx = x1 - x0 > 0 ? 0.05 * (x1 - x0) : (p->xlog ? 0.5 : 0.5 + 0.05 * fabs(x0));
    dy = y1 - y0 > 0 ? 0.08 * (y1 - y0) : (p->ylog ? 0.5 : 0.5 + 0.05 * fabs(y0));
    x0 -= dx;
    x1 += dx;
    y0 -= dy;
    /* room for the legend: about a tenth of the data's height per entry */
    for (int i = 0; i < p->nser; i++)
        room += p->ser[i].n > 0 ? 0.11 * (y1 - y0 > 0 ? y1 - y0 : 1) : 0;
    if (p->legend_low)
        y0 -= dy + room;
    else
        y1 += dy + room;
    r[0] = x0, r[1] = x1, r[2] = y0, r[3] = y1;
}

/* Viewport, window, the labelled box and the axis titles; then the bands (under everything) and
 * the grid over them. */
static void bn__frame(const bn__panel *p, const double r[4])
{
    static bn__labstep step;
    pladv(0);
    plvpor(0.15, 0.97, 0.12, 0.90);
    plwind(r[0], r[1], r[2], r[3]);
    plcol0(1);
    plwidth(1.0);
    pllsty(1);
    plschr(0, 0.9);
    /* log axes: a labelled decade every 1, 2, 3... decades so that at most ~9 labels show */
    step.x = p->xlog ? (int)ceil((r[1] - r[0]) / 9) : 1;
    step.y = p->ylog ? (int)ceil((r[3] - r[2]) / 9) : 1;
    plslabelfunc(bn__label, &step);
    plbox(p->xlog ? "bcgnstlo" : "bcgnst", 0, 0, p->ylog ? "bcgnstvlo" : "bcgnstv", 0, 0);
    plslabelfunc(NULL, NULL);
    pllab(p->xlab, "", p->title);
    plmtex("l", 5.2, 0.5, 0.5, p->ylab);
    for (int i = 0; i < p->nser; i++) {
        const bn__series *s = &p->ser[i];
        if (s->band && s->n >= 2 && bn__ok(s->y[0], p->ylog) && bn__ok(s->x[0], p->xlog) &&
            bn__ok(s->x[s->n - 1], p->xlog)) {
            PLFLT bx[4], by[4], top = bn__tr(s->y[0], p->ylog);
            bx[0] = bx[3] = bn__tr(s->x[0], p->xlog);
            bx[1] = bx[2] = bn__tr(s->x[s->n - 1], p->xlog);
            by[0] = by[1] = r[2];
            by[2] = by[3] = top > r[2] ? top : r[2];
            plcol0(BN__BAND_COLOR);
            plfill(4, bx, by);
        }
    }
    plcol0(1);
    plbox("bcgst", 0, 0, "bcgst", 0, 0);   /* the grid over the band */
}

/* The legend's entries, one per series drawn. */
typedef struct bn__legend {
    PLINT opts[BN__MAXSER], colors[BN__MAXSER], styles[BN__MAXSER], snum[BN__MAXSER];
    PLFLT widths[BN__MAXSER], sscale[BN__MAXSER];
    const char *text[BN__MAXSER], *syms[BN__MAXSER];
    int n;
} bn__legend;

/* Series i's line and symbols (a vertical line spans the window), and its legend entry. */
static void bn__series_draw(const bn__panel *p, int i, const double r[4], bn__legend *lg)
{
    const bn__series *s = &p->ser[i];
    PLFLT xs[BN__MAXPTS], ys[BN__MAXPTS];
    int m = 0, sym;
    for (int k = 0; k < s->n; k++)
        if (bn__ok(s->x[k], p->xlog) && bn__ok(s->y[k], p->ylog)) {
            xs[m] = bn__tr(s->x[k], p->xlog);
            ys[m] = bn__tr(s->y[k], p->ylog);
            m++;
        }
    if (m == 0)
        return;
    if (s->vline) {
        xs[1] = xs[0];
        ys[0] = r[2];
        ys[1] = r[3];
        m = 2;
    }
    sym = (s->symbol || m == 1) && !s->vline;
    plcol0(s->color);
    pllsty(s->style);
    plwidth(2.0);
    if (m > 1 && s->style > 0)
        plline(m, xs, ys);
    if (sym)
        plstring(m, xs, ys, bn__glyph(i));
    lg->opts[lg->n] = (s->style > 0 ? PL_LEGEND_LINE : 0) | (sym ? PL_LEGEND_SYMBOL : 0);
    lg->colors[lg->n] = s->color;
    lg->styles[lg->n] = s->style > 0 ? s->style : 1;
    lg->widths[lg->n] = 2.0;
    lg->sscale[lg->n] = 1.0;
    lg->snum[lg->n] = 1;
    lg->syms[lg->n] = bn__glyph(i);
    lg->text[lg->n] = s->label;
    lg->n++;
}

static void bn__draw(const bn__panel *p)
{
    double r[4];
    bn__legend lg;
    lg.n = 0;
    bn__ranges(p, r);
    bn__frame(p, r);
    for (int i = 0; i < p->nser; i++)
        bn__series_draw(p, i, r, &lg);
    pllsty(1);
    plwidth(1.0);
    plcol0(1);
    for (int i = 0; i < p->nnotes; i++)
        if (bn__ok(p->nx[i], p->xlog) && bn__ok(p->ny[i], p->ylog))
            plptex(bn__tr(p->nx[i], p->xlog), bn__tr(p->ny[i], p->ylog), 1, 0, -0.15, p->notes[i]);
    if (lg.n > 0) {
        PLFLT lw, lh;
        PLINT tcol[BN__MAXSER];
        for (int i = 0; i < lg.n; i++)
            tcol[i] = 1;
        pllegend(&lw, &lh, PL_LEGEND_BACKGROUND | PL_LEGEND_BOUNDING_BOX,
                 (p->legend_low ? PL_POSITION_BOTTOM | PL_POSITION_LEFT : PL_POSITION_TOP | PL_POSITION_RIGHT) |
                     PL_POSITION_INSIDE,
                 0.01, 0.01, 0.08, 0, 1, 1, 0, 0, lg.n, lg.opts, 0.8, 0.75, 1.8, 0.0, tcol, lg.text, NULL, NULL, NULL,
                 NULL, lg.colors, lg.styles, lg.widths, lg.colors, lg.sscale, lg.snum, lg.syms);
    }
}

static const char *bn__param_axis(bn_study_param p)
{
    switch (p) {
    case BN_STUDY_BOUNCES: return "bounces n (terms K^0 E .. K^n E)";
    case BN_STUDY_MAX_ITER: return "iteration limit (sweeps)";
    case BN_STUDY_TOL: return "tolerance (||r||_inf / ||E||_inf)";
    case BN_STUDY_PATCHES: return "patches";
    case BN_STUDY_PATCH_SIZE: return "largest patch edge (scene units)";
    case BN_STUDY_SAMPLES: return "form-factor samples per pair";
    case BN_STUDY_FF: return "form-factor method";
    case BN_STUDY_SPP: return "path-tracer samples per patch (spp)";
    case BN_STUDY_PRECISION: return "storage precision of F";
    case BN_STUDY_EPS: return "hierarchy eps (x largest emission)";
    }
    return "";
}

/* Fills the two panels from the result. */
/* Mesh studies: the least-squares slope of log(per-surface error) against log(h), h the patch size
 * (patch-size studies) or patches^(-1/2) (patches studies): the observed order p of err ~ h^p.
 * NAN for other studies or fewer than two usable rows. */
static double bn__fit_order(const bn_study_result *r)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    int m = 0;
    if (r->param != BN_STUDY_PATCHES && r->param != BN_STUDY_PATCH_SIZE)
        return NAN;
    for (size_t i = 0; i < r->nrows; i++) {
        const bn_study_row *w = &r->rows[i];
        double h = r->param == BN_STUDY_PATCHES ? pow((double)w->patches, -0.5) : w->x, e = w->err_surface_max;
        if (strcmp(w->method, "radiosity") != 0 || !(h > 0) || !(e > 0))
            continue;
        sx += log(h);
        sy += log(e);
        sxx += log(h) * log(h);
        sxy += log(h) * log(e);
        m++;
    }
    if (m < 2 || m * sxx - sx * sx <= 0)
        return NAN;
    return (m * sxy - sx * sy) / (m * sxx - sx * sx);
}

/* The distinct methods of the rows, in order of first appearance. */
static int bn__methods_of(const bn_study_result *r, const char **methods)
{
    int nm = 0;
    for (size_t i = 0; i < r->nrows && nm < BN__MAXSER; i++) {
        int seen = 0;
        for (int k = 0; k < nm; k++)
            seen |= strcmp(methods[k], r->rows[i].method) == 0;
        if (!seen)
            methods[nm++] = r->rows[i].method;
    }
    return nm;
}

/* One series per method of the rows, y against x as `pick` reads them from a row. */
static void bn__by_method(bn__panel *pn, const bn_study_result *r, const char **methods, int nm,
                          void (*pick)(const bn_study_row *w, double *x, double *y))
{
    for (int k = 0; k < nm; k++) {
        bn__series *s = bn__add(pn, methods[k], 1, 1);
        for (size_t i = 0; i < r->nrows; i++)
            if (strcmp(r->rows[i].method, methods[k]) == 0) {
                double x, y;
                pick(&r->rows[i], &x, &y);
                bn__pt(s, x, y);
            }
    }
}

static void bn__pick_solve(const bn_study_row *w, double *x, double *y) { *x = w->t_solve, *y = w->err_inf_rel; }
static void bn__pick_total(const bn_study_row *w, double *x, double *y) { *x = w->t_total, *y = w->err_surface_max; }
static void bn__pick_tol(const bn_study_row *w, double *x, double *y) { *x = w->x, *y = w->t_solve; }

/* Panel a: error against time: the solvers' curves on one K (operator studies), or every setting's
 * total time (the others), with the tracer's target. */
static void bn__panel_time(const bn_study_result *r, int op, const char **methods, int nm, bn__panel *a)
{
    a->xlog = a->ylog = 1;
    a->legend_low = 1;
    snprintf(a->xlab, sizeof a->xlab, "time (s)");
    if (op) {
        snprintf(a->ylab, sizeof a->ylab, "||L - L#dref#u||#d∞#u / ||L#dref#u||#d∞#u");
        snprintf(a->title, sizeof a->title, "error against time (%zu patches)", r->ref_patches);
        if (r->ncurves == 0)
            bn__by_method(a, r, methods, nm, bn__pick_solve);   /* the solve: K is shared */
        for (size_t c = 0; c < r->ncurves; c++) {
            int direct = strcmp(r->curves[c].label, "direct") == 0;
            bn__series *s = bn__add(a, direct ? "direct (exact to rounding)" : r->curves[c].label, direct ? 2 : 1, 0);
            if (s)
                s->vline = direct;
            /* S_0 = E costs no time: the series is drawn from S_1 */
            for (size_t k = strcmp(r->curves[c].label, "truncated series") == 0 ? 1 : 0; k < r->curves[c].n; k++)
                bn__pt(s, r->curves[c].t[k], r->curves[c].err[k]);
        }
        return;
    }
    snprintf(a->ylab, sizeof a->ylab, "max per-surface relative error");
    snprintf(a->title, sizeof a->title, "error against time (all phases)");
    bn__by_method(a, r, methods, nm, bn__pick_total);
    if (!isnan(r->best_trace)) {
        bn__series *s = bn__add(a, "target", 2, 0);
        double t0 = INFINITY, t1 = 0;
        for (size_t i = 0; i < r->nrows; i++) {
            t0 = fmin(t0, r->rows[i].t_total);
            t1 = fmax(t1, r->rows[i].t_total);
        }
        bn__pt(s, t0, r->target);
        bn__pt(s, t1, r->target);
    }
}

/* Panel b of a bounces study: the truncation error, its bounds and estimate, the reference's own. */
static void bn__panel_bounces(const bn_study_result *r, bn__panel *b)
{
    bn__series *m = bn__add(b, "measured ||L - S#dn#u||#d∞#u", 1, 1);
    bn__series *bd = bn__add(b, "bound ||K||#un+1#d/(1-||K||) ||E||", 2, 0);
    bn__series *bk = bn__add(b, "bound ||K||#un#d/(1-||K||) ||KE||", 2, 0);
    bn__series *es = bn__add(b, "estimate #gr/(1-#gr) ||K#un#d E||", 3, 0);
    bn__series *fl = bn__add(b, "reference's own error", 4, 0);   /* drawn when within 1e3 of the data */
    double n0 = INFINITY, n1 = -INFINITY, emin = INFINITY;
    snprintf(b->ylab, sizeof b->ylab, "||L - S#dn#u||#d∞#u (W m#u-2#d sr#u-1#d)");
    snprintf(b->title, sizeof b->title, "truncation error: ||K||#d∞#u = %.4g, #gr(K) ~ %.4g", r->k_norm,
             r->spectral_radius);
    for (size_t i = 0; i < r->nrows; i++)
        if (strcmp(r->rows[i].method, "truncated") == 0) {
            bn__pt(m, r->rows[i].x, r->rows[i].err_inf);
            bn__pt(bd, r->rows[i].x, r->rows[i].bound);
            bn__pt(bk, r->rows[i].x, r->rows[i].bound_ke);
            bn__pt(es, r->rows[i].x, r->rows[i].estimate);
            n0 = fmin(n0, r->rows[i].x);
            n1 = fmax(n1, r->rows[i].x);
            if (r->rows[i].err_inf > 0)
                emin = fmin(emin, r->rows[i].err_inf);
        }
    if (r->ref_error > 0 && isfinite(n0) && r->ref_error * r->norm_L > 1e-3 * emin) {
        bn__pt(fl, n0, r->ref_error * r->norm_L);
        bn__pt(fl, n1, r->ref_error * r->norm_L);
    }
}

/* Panel b of an iteration-limit study: the error after k sweeps and each method's a priori bound. */
static void bn__panel_max_iter(const bn_study_result *r, const char **methods, int nm, bn__panel *b)
{
    b->xlog = 1;
    snprintf(b->ylab, sizeof b->ylab, "||L - L#dk#u||#d∞#u (W m#u-2#d sr#u-1#d)");
    snprintf(b->title, sizeof b->title, "error after k sweeps, and the a priori bound (dashed)");
    for (int k = 0; k < nm; k++) {
        bn__series *s = bn__add(b, methods[k], 1, 1), *bd;
        char lab[64];
        snprintf(lab, sizeof lab, "%s bound", methods[k]);
        bd = bn__add(b, lab, 2, 0);
        if (bd)
            bd->color = s ? s->color : 2;
        for (size_t i = 0; i < r->nrows; i++)
            if (strcmp(r->rows[i].method, methods[k]) == 0) {
                bn__pt(s, r->rows[i].x, r->rows[i].err_inf);
                bn__pt(bd, r->rows[i].x, r->rows[i].bound);
            }
    }
}

/* Panel b of the mesh and form-factor studies: the errors against the setting, the reference's own
 * error as a band, and (mesh studies) the fitted convergence order in the title. */
static void bn__panel_errors(const bn_study_result *r, bn__panel *b)
{
    int categorical = r->param == BN_STUDY_FF || r->param == BN_STUDY_PRECISION, idx = 0;
    bn__series *sm = bn__add(b, "max per-surface", 1, 1), *pm = bn__add(b, "max per-patch", 1, 1);
    bn__series *rm = bn__add(b, "RMS per-patch", 1, 1), *em = bn__add(b, "reflected power", 1, 1);
    bn__series *fl = bn__add(b, "reference's own error, per surface (shaded)", 2, 0);
    double x0 = INFINITY, x1 = -INFINITY, p = bn__fit_order(r);
    b->xlog = !categorical;
    snprintf(b->ylab, sizeof b->ylab, "relative error");
    snprintf(b->title, sizeof b->title, "error vs %s (ref. %zu patches)", bn_study_param_name(r->param),
             r->ref_patches);
    if (categorical)
        snprintf(b->xlab, sizeof b->xlab, "%s (setting)", bn__param_axis(r->param));
    for (size_t i = 0; i < r->nrows; i++) {
        const bn_study_row *w = &r->rows[i];
        double x;
        if (strcmp(w->method, "trace") == 0 && r->param != BN_STUDY_SPP)
            continue;   /* the tracer rows of an equal-error study are on the time panel */
        x = categorical ? ++idx : (r->param == BN_STUDY_PATCHES ? (double)w->patches : w->x);
        bn__pt(sm, x, w->err_surface_max);
        bn__pt(pm, x, w->err_max_rel);
        bn__pt(rm, x, w->err_rms_rel);
        bn__pt(em, x, w->err_energy_rel);
        x0 = fmin(x0, x);
        x1 = fmax(x1, x);
        if (categorical && b->nnotes < 8) {
            snprintf(b->notes[b->nnotes], sizeof b->notes[0], "%s", w->value);
            b->nx[b->nnotes] = x;
            b->ny[b->nnotes] = w->err_surface_max;
            b->nnotes++;
        }
    }
    if (r->ref_error > 0 && isfinite(x0)) {
        bn__pt(fl, x0, r->ref_error);
        bn__pt(fl, x1, r->ref_error);
        fl->band = 1;
    }
    /* the fitted convergence order of the per-surface error: err ~ h^p, h ~ patches^-1/2 */
    if (isfinite(p))
        snprintf(b->title + strlen(b->title), sizeof b->title - strlen(b->title), ", fitted order %.2f", p);
}

static void bn__panels(const bn_study_result *r, bn__panel *a, bn__panel *b)
{
    const char *methods[BN__MAXSER];
    int nm = bn__methods_of(r, methods);
    int op = r->param == BN_STUDY_BOUNCES || r->param == BN_STUDY_MAX_ITER || r->param == BN_STUDY_TOL;
    memset(a, 0, sizeof *a);
    memset(b, 0, sizeof *b);
    bn__panel_time(r, op, methods, nm, a);
    snprintf(b->xlab, sizeof b->xlab, "%s", bn__param_axis(r->param));
    b->ylog = 1;
    if (r->param == BN_STUDY_BOUNCES)
        bn__panel_bounces(r, b);
    else if (r->param == BN_STUDY_MAX_ITER)
        bn__panel_max_iter(r, methods, nm, b);
    else if (op) {   /* tol */
        b->xlog = 1;
        snprintf(b->ylab, sizeof b->ylab, "time to tolerance (s)");
        snprintf(b->title, sizeof b->title, "time to each tolerance, same K (%zu patches)", r->ref_patches);
        bn__by_method(b, r, methods, nm, bn__pick_tol);
    } else
        bn__panel_errors(r, b);
}

static void bn__palette(void)
{
    static const int pal[10][3] = {{255, 255, 255}, {0, 0, 0},     {31, 119, 180}, {214, 39, 40},  {44, 160, 44},
                                   {148, 103, 189}, {255, 127, 14}, {140, 86, 75},  {227, 119, 194}, {23, 190, 207}};
    plscolbg(255, 255, 255);
    for (int i = 0; i < 10; i++)
        plscol0(i, pal[i][0], pal[i][1], pal[i][2]);
    plscol0(BN__BAND_COLOR, 221, 221, 221);   /* the reference's error band */
}

static bn_status bn__plot_one(const bn__panel *a, const bn__panel *b, const char *title, const char *path,
                              const char *device, bn_error *err)
{
    char *tmp = NULL;
    bn_status st = bn__tmpname_reserve(path, &tmp, err);
    if (st != BN_OK)
        return st;
    plsdev(device);
    plsfnam(tmp);
    plspage(0, 0, 1400, 560, 0, 0);
    bn__palette();
    plssub(2, 1);
    plinit();
    plfontld(1);
    bn__draw(a);
    bn__draw(b);
    plend();
    (void)title;
    return bn__tmpname_commit(path, tmp, err);
}

bn_status bn_study_plot(const bn_study_result *r, const char *prefix, const char *title, bn_error *err)
{
    bn__panel *a = bn__calloc(2, sizeof *a);
    char path[4096];
    bn_status st;
    if (!a)
        return bn_error_set(err, BN_ENOMEM, "study plot: out of memory");
    bn__panels(r, &a[0], &a[1]);
    if (title && *title) {
        char t[sizeof a[0].title];
        snprintf(t, sizeof t, "%.40s: %.80s", title, a[0].title);
        memcpy(a[0].title, t, sizeof t);
    }
    snprintf(path, sizeof path, "%s.png", prefix);
    st = bn__plot_one(&a[0], &a[1], title, path, "pngcairo", err);
    if (st == BN_OK) {
        snprintf(path, sizeof path, "%s.svg", prefix);
        st = bn__plot_one(&a[0], &a[1], title, path, "svg", err);
    }
    free(a);
    return st;
}

bn_status bn__study_panel_svg(const bn_study_result *r, int which, const char *beside, char **svg, bn_error *err)
{
    bn__panel *a = bn__calloc(2, sizeof *a);
    char *tmp = NULL;
    size_t n;
    bn_status st;
    *svg = NULL;
    if (!a)
        return bn_error_set(err, BN_ENOMEM, "study plot: out of memory");
    bn__panels(r, &a[0], &a[1]);
    st = bn__tmpname_reserve(beside, &tmp, err);   /* a temporary beside the report, removed below */
    if (st == BN_OK) {
        plsdev("svg");
        plsfnam(tmp);
        plspage(0, 0, 700, 560, 0, 0);
        bn__palette();
        plssub(1, 1);
        plinit();
        plfontld(1);
        bn__draw(&a[which ? 1 : 0]);
        plend();
        st = bn__read_file(tmp, svg, &n, err);
        bn__tmpname_abort(tmp);   /* removes it */
    }
    free(a);
    return st;
}
