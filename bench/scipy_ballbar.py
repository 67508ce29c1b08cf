#!/usr/bin/python3
# SPDX-License-Identifier: Apache-2.0
"""Kim's 32-point ball-bar calibration solved by SciPy, the reference for cpmd's own solver.

Reads the problem cpm_perf exported (actuator readings, bar lengths, nominal
pivot, d0, start point, the C++ solution and its standard errors), solves the
SAME residual with the same analytic Jacobian as calibration/src/ballbar.cpp
(ballbar_residuals, with the bar length known: 9 unknowns), times it, and
compares the solutions.

    /usr/bin/python3 bench/scipy_ballbar.py PROBLEM.json [--repeat N] [--json OUT]

Debian's python3-scipy; the `python3` on PATH may be another interpreter
without SciPy, so bench/run.sh calls /usr/bin/python3.

Residual (Kim eqs. 15-17, ball-bar frame), eta = (c1, c2, theta_z, c3,
theta_x, theta_y, dq_x, dq_y, dq_z):
    U = [u1; u2; u3],  u1 = (1, 0, 0),  u2 = (-sin tz, cos tz, 0),
    u3 = (cos tx sin ty, -sin tx, cos tx cos ty)
    p_j = U^-1 ((d_j + d0) .* c),   h_j = |p_j - (q + dq)| - l_j
"""
import argparse
import json
import statistics
import sys
import time

t_import = time.perf_counter()
import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402
import scipy  # noqa: E402

IMPORT_S = time.perf_counter() - t_import


def frame(eta):
    tz, tx, ty = eta[2], eta[4], eta[5]
    sz, cz, sx, cx, sy, cy = np.sin(tz), np.cos(tz), np.sin(tx), np.cos(tx), np.sin(ty), np.cos(ty)
    U = np.array([[1.0, 0.0, 0.0], [-sz, cz, 0.0], [cx * sy, -sx, cx * cy]])
    du2_dtz = np.array([-cz, -sz, 0.0])
    du3_dtx = np.array([-sx * sy, -cx, -sx * cy])
    du3_dty = np.array([cx * cy, 0.0, -cx * sy])
    return U, du2_dtz, du3_dtx, du3_dty


class Problem:
    def __init__(self, doc):
        self.d0 = np.array(doc["d0"], dtype=float)
        self.pivot = np.array(doc["pivot"], dtype=float)
        self.d = np.array(doc["d"], dtype=float)            # N x 3 (m)
        self.length = np.array(doc["length"], dtype=float)  # N (m)
        self.eta0 = np.array(doc["eta0"], dtype=float)
        self.D = self.d + self.d0                           # d_j + d0, fixed

    def _geometry(self, eta):
        U, a, b, c = frame(eta)
        W = np.linalg.inv(U)
        s = self.D * np.array([eta[0], eta[1], eta[3]])
        p = s @ W.T                                  # rows p_j = W s_j
        v = p - (self.pivot + eta[6:9])
        ln = np.linalg.norm(v, axis=1)
        return W, p, v, ln, a, b, c

    def residual(self, eta):
        _, _, _, ln, _, _, _ = self._geometry(eta)
        return ln - self.length

    def jacobian(self, eta):
        W, p, v, ln, du2_dtz, du3_dtx, du3_dty = self._geometry(eta)
        e = v / ln[:, None]
        g = e @ W                                    # rows g_j = W^T e_j
        J = np.empty((len(ln), 9))
        J[:, 0] = g[:, 0] * self.D[:, 0]
        J[:, 1] = g[:, 1] * self.D[:, 1]
        J[:, 2] = -g[:, 1] * (p @ du2_dtz)
        J[:, 3] = g[:, 2] * self.D[:, 2]
        J[:, 4] = -g[:, 2] * (p @ du3_dtx)
        J[:, 5] = -g[:, 2] * (p @ du3_dty)
        J[:, 6:9] = -e
        return J


def solve(P, method, tol):
    # x_scale='jac': MINPACK's own column scaling, as cpmd's LM scales by the Jacobian's columns.
    return least_squares(P.residual, P.eta0, jac=P.jacobian, method=method, x_scale="jac",
                         ftol=tol["cost"], xtol=tol["step"], gtol=tol["gradient"])


def timed(P, method, tol, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = solve(P, method, tol)
        times.append(time.perf_counter() - t0)
    times.sort()
    return r, times


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("problem")
    ap.add_argument("--repeat", type=int, default=200)
    ap.add_argument("--json", help="write the result here (default: stdout)")
    a = ap.parse_args()
    with open(a.problem) as f:
        doc = json.load(f)
    P = Problem(doc)
    tol = doc["tolerances"]
    cpp = doc["cpp"]
    eta_cpp = np.array(cpp["eta"])
    se = np.array(cpp["std_error"])
    out = {"scipy_version": scipy.__version__, "numpy_version": np.__version__,
           "python": sys.version.split()[0], "import_s": IMPORT_S, "repeat": a.repeat,
           "residual_check_max_m": None, "methods": {}}
    # The same residual: at the C++ solution both codes must give the same h_j.
    r_here = P.residual(eta_cpp)
    out["residual_check_max_m"] = float(np.max(np.abs(r_here - np.array(cpp["residual"]))))
    for method in ("lm", "trf"):
        r, times = timed(P, method, tol, a.repeat)
        diff = r.x - eta_cpp
        out["methods"][method] = {
            "median_s": statistics.median(times),
            "min_s": times[0],
            "p90_s": times[min(len(times) - 1, int(0.9 * len(times)))],
            "success": bool(r.success),
            "status": int(r.status),
            "message": r.message,
            "nfev": int(r.nfev),
            "njev": int(r.njev) if r.njev is not None else None,
            "cost": float(r.cost),                  # 1/2 |r|^2 (m^2), as cpmd's final_cost
            "eta": r.x.tolist(),
            "max_abs_diff_sigma": float(np.max(np.abs(diff) / se)),
            "max_abs_diff": {n: float(abs(x)) for n, x in zip(doc["names"], diff)},
        }
    text = json.dumps(out, indent=1)
    if a.json:
        with open(a.json, "w") as f:
            f.write(text + "\n")
    else:
        print(text)


if __name__ == "__main__":
    main()
