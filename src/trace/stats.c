/* Upper-tail quantiles of the standard normal and Student's t, for Sidak-corrected bounds.
 * t tail: P(T > x) = I_{nu / (nu + x^2)}(nu / 2, 1 / 2) / 2, with the regularised incomplete beta by
 * its continued fraction (modified Lentz; Numerical Recipes 3rd ed. 6.4). Quantiles by bisection. */
#include "bounce/trace.h"

#include <float.h>
#include <math.h>

/* One step of the modified Lentz recurrence with coefficient aa: updates c and d, returns d c. */
static double bn__lentz_step(double aa, double *c, double *d)
{
    const double tiny = 1e-300;
    *d = 1 + aa * *d;
    if (fabs(*d) < tiny)
        *d = tiny;
    *c = 1 + aa / *c;
    if (fabs(*c) < tiny)
        *c = tiny;
    *d = 1 / *d;
    return *d * *c;
}

static double bn__betacf(double a, double b, double x)
{
    double qab = a + b, qap = a + 1, qam = a - 1, c = 1, d = 1 - qab * x / qap, h;
    if (fabs(d) < 1e-300)
        d = 1e-300;
    d = 1 / d;
    h = d;
    for (int m = 1; m <= 10000; m++) {
        int m2 = 2 * m;
        double del;
        h *= bn__lentz_step(m * (b - m) * x / ((qam + m2) * (a + m2)), &c, &d);   /* the even step */
        del = bn__lentz_step(-(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)), &c, &d);   /* the odd step */
        h *= del;
        if (fabs(del - 1) < 4 * DBL_EPSILON)
            break;
    }
    return h;
}

/* Regularised incomplete beta I_x(a, b). */
static double bn__betai(double a, double b, double x)
{
    double lbt;
    if (x <= 0)
        return 0;
    if (x >= 1)
        return 1;
    lbt = lgamma(a + b) - lgamma(a) - lgamma(b) + a * log(x) + b * log1p(-x);
    if (x < (a + 1) / (a + b + 2))
        return exp(lbt) * bn__betacf(a, b, x) / a;
    return 1 - exp(lbt) * bn__betacf(b, a, 1 - x) / b;
}

static double bn__normal_upper(double x) { return 0.5 * erfc(x / sqrt(2.0)); }

static double bn__t_upper(double x, double nu)
{
    if (x <= 0)
        return 0.5;
    return 0.5 * bn__betai(0.5 * nu, 0.5, nu / (nu + x * x));
}

static double bn__bisect(double (*tail)(double, double), double nu, double p)
{
    double lo = 0, hi = 1;
    if (!(p > 0))
        return INFINITY;
    if (p >= 0.5)
        return 0;
    while (tail(hi, nu) > p && hi < 1e150)
        hi *= 2;
    for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; i++) {
        double mid = 0.5 * (lo + hi);
        if (tail(mid, nu) > p)
            lo = mid;
        else
            hi = mid;
    }
    return 0.5 * (lo + hi);
}

static double bn__normal_tail2(double x, double nu)
{
    (void)nu;
    return bn__normal_upper(x);
}

double bn_normal_quantile_upper(double p) { return bn__bisect(bn__normal_tail2, 0, p); }

double bn_student_t_quantile_upper(double p, double dof)
{
    if (!(dof > 0))
        return INFINITY;
    if (dof > 1e7)
        return bn_normal_quantile_upper(p);
    return bn__bisect(bn__t_upper, dof, p);
}
