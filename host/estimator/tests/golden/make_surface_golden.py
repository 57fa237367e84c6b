#!/usr/bin/env python3
"""Golden values for the B-spline surface (host/estimator/src/surface.rs), computed with SciPy.

Run from anywhere: `python3 make_surface_golden.py` rewrites surface_golden.json beside this script.
Needs numpy and scipy >= 1.12 (for NdBSpline). The control nets are random (fixed seeds), the knots clamped
uniform as in surface.rs / geomdl: p + 1 zeros, interior knots j / (n - p + 1), p + 1 ones; u runs along the
rows (first index, degree_u), v along the columns (degree_v). Each value is checked against a second SciPy
route (1-D BSpline along v, then along u) before it is written.
"""
import json
import pathlib

import numpy as np
import scipy
from scipy.interpolate import BSpline, NdBSpline


def clamped_uniform(degree, points):
    interior = points - 1 - degree
    return [0.0] * (degree + 1) + [j / (interior + 1) for j in range(1, interior + 1)] + [1.0] * (degree + 1)


def parameters(knots, rng, count):
    """Ends, every distinct knot (span boundaries are where off-by-one errors live), and random values."""
    values = {0.0, 1.0}
    values.update(knots)
    values.update(rng.uniform(0.0, 1.0, count).tolist())
    return sorted(values)


def case(seed, rows, cols, degree_u, degree_v):
    rng = np.random.default_rng(seed)
    # A perturbed lattice like the sensor's (pitch ~80 px) so values look like real control points.
    grid = np.stack(np.meshgrid(np.arange(cols) * 80.0, np.arange(rows) * 80.0), axis=-1)
    net = grid + rng.normal(0.0, 6.0, size=(rows, cols, 2)) + np.array([400.0, 200.0])
    tu = clamped_uniform(degree_u, rows)
    tv = clamped_uniform(degree_v, cols)
    surface = NdBSpline((np.array(tu), np.array(tv)), net, (degree_u, degree_v))
    us = parameters(tu, rng, 6)
    vs = parameters(tv, rng, 6)
    samples = []
    for u in us:
        # Second route: curves along v for each row, then one curve along u through them.
        along_v = np.array([BSpline(np.array(tv), net[r], degree_v)(vs) for r in range(rows)])  # rows x len(vs) x 2
        column = BSpline(np.array(tu), along_v, degree_u)(u)  # len(vs) x 2
        for j, v in enumerate(vs):
            x, y = surface([[u, v]])[0]
            assert abs(x - column[j][0]) < 1e-9 and abs(y - column[j][1]) < 1e-9, (u, v, x, column[j])
            samples.append([u, v, float(x), float(y)])
    return {
        "seed": seed,
        "rows": rows,
        "cols": cols,
        "degree_u": degree_u,
        "degree_v": degree_v,
        "knots_u": tu,
        "knots_v": tv,
        "control_points": net.reshape(-1, 2).tolist(),
        "samples": samples,
    }


def main():
    cases = [
        case(1, 11, 15, 1, 1),  # the real pad's corner lattice, the paper's degree
        case(2, 6, 8, 2, 2),
        case(3, 7, 9, 3, 3),
        case(4, 5, 6, 2, 3),
        case(5, 11, 15, 3, 3),
        case(6, 4, 4, 3, 3),  # Bezier patch: no interior knots
        case(7, 9, 5, 1, 3),
    ]
    out = {
        "generator": "make_surface_golden.py with numpy %s, scipy %s (NdBSpline)" % (np.__version__, scipy.__version__),
        "layout": "control_points row-major rows x cols; u along rows (degree_u), v along columns (degree_v); "
        "samples are [u, v, x, y]",
        "cases": cases,
    }
    path = pathlib.Path(__file__).with_name("surface_golden.json")
    path.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {path}: {len(cases)} cases, {sum(len(c['samples']) for c in cases)} samples")


if __name__ == "__main__":
    main()
