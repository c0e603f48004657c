#!/usr/bin/env python3
"""The peer of rouen's sky fit in bench/sky_bench.cc: the same seven-parameter model
(Yu & Malik 1998, eq. 9) fitted per colour channel with scipy.optimize.least_squares.

Input (argv[1]): a text file of skies. Each sky is a line "sky NAME SX SY SZ N" (sun direction,
ENU) followed by N lines "X Y Z R G B W" (a unit direction above the horizon, its radiance and
its weight: the sample's term of the objective is multiplied by W, as in rouen's fit).
Output (stdout): one JSON object per sky and line: {"name", "seconds", "channels": [[Lz, a, b,
c, d, e, h] x 3], "cost"}; seconds is the wall time of the three fits alone.

The fit: relative residuals model/y - 1 under scipy's soft_l1 loss (a smooth L1, as robust to
outliers as rouen's default relative-L1 objective), each sample's loss times its weight
(normalised to mean 1), trust-region reflective within the model's
box bounds, from the CIE general-sky shapes and Preetham's turbidity 3 and 6 skies plus
`--random` random starts, each with Lz in closed form; the lowest cost wins.
"""
import json
import sys
import time

import numpy as np
from scipy.optimize import least_squares

LOWER = np.array([1e-12, -3.0, -10.0, 0.0, -20.0, -0.9, 0.3])
UPPER = np.array([np.inf, 30.0, -0.01, 200.0, -0.01, 20.0, 3.0])
STARTS = [  # {a, b, c, d, e, h}
    (-1.0, -0.32, 10.0, -3.0, 0.45, 1.0),
    (-1.0, -0.32, 16.0, -3.0, 0.30, 1.0),
    (-1.0, -0.55, 5.0, -2.5, 0.30, 1.0),
    (0.0, -1.0, 2.0, -1.5, 0.15, 1.0),
    (1.1, -0.8, 0.0, -1.0, 0.0, 1.0),
    (-0.927, -0.639, 5.257, -2.215, 0.169, 1.0),
    (-0.391, -1.705, 5.189, -1.853, -0.032, 1.0),
    (-1.0, -0.32, 10.0, -3.0, 0.45, 0.6),
]


def shape(p, inv_cos_xi, log_gamma, cos2_gamma):
    a, b, c, d, e, h = p
    return (1 + a * np.exp(b * inv_cos_xi)) * (1 + c * np.exp(d * np.exp(h * log_gamma)) +
                                               e * cos2_gamma)


def weighted_soft_l1(w):
    """scipy's soft_l1 loss rho(z) = 2 (sqrt(1 + z) - 1) with its derivatives, times w."""
    def loss(z):
        t = 1 + z
        return np.vstack([w * 2 * (t**0.5 - 1), w * t**-0.5, w * -0.5 * t**-1.5])
    return loss


def fit_channel(y, w, geom, random_starts, rng):
    inv_cos_xi, log_gamma, cos2_gamma = geom
    loss = weighted_soft_l1(w)

    def residuals(q):
        return q[0] * shape(q[1:], inv_cos_xi, log_gamma, cos2_gamma) / y - 1

    starts = [np.array(s) for s in STARTS]
    for _ in range(random_starts):
        starts.append(rng.uniform(np.maximum(LOWER[1:], -20), np.minimum(UPPER[1:], 20)))
    best = None
    for s in starts:
        f = shape(s, inv_cos_xi, log_gamma, cos2_gamma)
        ratio = f / y
        if not np.all(np.isfinite(ratio)) or np.sum(ratio * ratio) <= 0:
            continue
        lz = np.sum(w * ratio) / np.sum(w * ratio * ratio)  # least squares of lz f / y = 1
        q0 = np.clip(np.concatenate([[max(lz, 1e-9)], s]), LOWER, np.minimum(UPPER, 1e300))
        try:
            r = least_squares(residuals, q0, bounds=(LOWER, UPPER), loss=loss,
                              f_scale=0.01, method="trf", x_scale="jac", max_nfev=400)
        except (ValueError, FloatingPointError):
            continue
        if np.isfinite(r.cost) and (best is None or r.cost < best.cost):
            best = r
    return best


def main():
    path = sys.argv[1]
    random_starts = int(sys.argv[2]) if len(sys.argv) > 2 else 8
    rng = np.random.default_rng(5)
    with open(path) as f:
        lines = f.read().split("\n")
    i = 0
    np.seterr(all="ignore")
    while i < len(lines):
        head = lines[i].split()
        i += 1
        if not head:
            continue
        name, sun, n = head[1], np.array([float(v) for v in head[2:5]]), int(head[5])
        data = np.loadtxt(lines[i:i + n], ndmin=2)
        i += n
        dirs, rad, w = data[:, :3], data[:, 3:6], data[:, 6] / np.mean(data[:, 6])
        t0 = time.perf_counter()
        inv_cos_xi = 1.0 / np.maximum(dirs[:, 2], 0.01)
        gamma = np.arccos(np.clip(dirs @ sun, -1, 1))
        geom = (inv_cos_xi, np.log(np.maximum(gamma, 1e-6)), np.cos(gamma)**2)
        fits = [fit_channel(rad[:, c], w, geom, random_starts, rng) for c in range(3)]
        seconds = time.perf_counter() - t0
        print(json.dumps({
            "name": name,
            "seconds": seconds,
            "channels": [list(map(float, f.x)) if f is not None else None for f in fits],
            "cost": sum(float(f.cost) for f in fits if f is not None),
        }), flush=True)


if __name__ == "__main__":
    main()
