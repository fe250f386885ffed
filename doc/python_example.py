#!/usr/bin/env python3
"""Light transport bounce by bounce from Python, on the Cornell box: the power each term K^k E
carries and the error of the truncated series E + KE + ... + K^K E against the full solution L, and
the contact sheet of `bounce bounces` made again from Python's images (render()). Writes a table to
stdout and, when matplotlib is there, the plot and the sheet (PNG) beside the given path.

    PYTHONPATH=python /usr/bin/python3 doc/python_example.py [out_prefix] [patches]

Run by the tests (tests/python/test_bounce.py) so that it keeps working.
"""
import os
import sys

import numpy as np

import bounce

here = os.path.dirname(os.path.abspath(__file__))
prefix = sys.argv[1] if len(sys.argv) > 1 else "cornell-bounces"
patches = int(sys.argv[2]) if len(sys.argv) > 2 else None   # None: bounce's default mesh
K = 10
r = bounce.solve(os.path.join(here, "..", "meshes", "cornell-box.obj"), unit="mm", bounces=K, tol=1e-10,
                 patches=patches)
area_m2 = r.area * 1e-6                      # mm^2 -> m^2
power = [np.pi * (area_m2[:, None] * t).sum() for t in r.terms]   # W, summed over R, G, B
L_power = np.pi * (area_m2[:, None] * r.L).sum()
partial = np.zeros_like(r.L)
print("k  power(K^k E) W   share of L   max rel. error of E+...+K^k E")
errors = []
for k, t in enumerate(r.terms):
    partial += t
    err = np.abs(partial - r.L).max() / np.abs(r.L).max()
    errors.append(err)
    print("%-2d %12.6g   %8.3f%%   %10.3e" % (k, power[k], 100 * power[k] / L_power, err))
print("L  %12.6g   %8.3f%%   (rest after K%dE: %.3g W)" % (L_power, 100.0, K,
                                                           np.pi * (area_m2[:, None] * r.rest).sum()))
# the truncation error falls geometrically, as the spectral radius of K: the last ratios say how fast
ratios = [errors[k + 1] / errors[k] for k in range(K - 3, K)]
print("error ratio per bounce (last three): " + " ".join("%.3f" % q for q in ratios))

# the contact sheet: every layer side by side, row 1 at L's exposure, row 2 each layer at its own
# (bounce's rule: the 99th percentile luminance at 0.9), as `bounce bounces` makes cornell.sheet.png
img = bounce.solve(os.path.join(here, "..", "meshes", "cornell-box.obj"), unit="mm", bounces=3,
                   patches=patches).render(size=(160, 160))


def exposure(rgb):
    y = (rgb @ np.array([0.2126, 0.7152, 0.0722])).ravel()
    y = y[y > 0]
    return 0.9 / np.quantile(y, 0.99) if y.size else 1.0


def srgb(x):
    x = np.clip(x, 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


sL = exposure(img["L"])
sheet = np.vstack([np.hstack([srgb(a * sL) for a in img.values()]),
                   np.hstack([srgb(a * exposure(a)) for a in img.values()])])
print("contact sheet: %s, %d x %d pixels" % (" ".join(img), sheet.shape[1], sheet.shape[0]))
try:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))
    ax[0].bar(range(K + 1), power)
    ax[0].set_xlabel("bounce k (term K^k E)")
    ax[0].set_ylabel("power (W)")
    ax[1].semilogy(range(K + 1), errors, "o-")
    ax[1].set_xlabel("terms kept, E .. K^k E")
    ax[1].set_ylabel("max relative error against L")
    fig.tight_layout()
    fig.savefig(prefix + ".png", dpi=90)
    plt.imsave(prefix + ".sheet.png", sheet)
    print("wrote " + prefix + ".png and " + prefix + ".sheet.png")
except ImportError:
    print("matplotlib is not installed: no plot")
