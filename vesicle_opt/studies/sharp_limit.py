"""The eps -> 0 consistency of the phase-field problem (6)-(8) in 2D ([9] of the paper): equilibria at
eps = 0.2 ... 0.05 (ratio sqrt 2: eps, eps/2, eps/4 and the two between) with h proportional to eps (eps/h fixed), their observed order in eps, the
Richardson-extrapolated reduced energies, and the distance to the sharp-interface closed elastica of
``vesicle_opt.sharp.elastica`` (a spectral tangent-angle discretisation sharing no code with the
phase-field path).

Points: reduced areas nu = 4 pi V / S^2 in ``NUS`` at the perimeter S = 3 pi (R0 = 1.5), set by
``constraints.reduced_volume`` and ``constraints.area`` (geometry.targets: V = (|Omega| + alpha)/2,
S = 3 sqrt 2 beta / 4). Box [-3, 3] x [-2, 2], periodic: the elastica of nu in [0.6, 0.95] spans at
most 4.05 x 2.40 (measured from the reference curves), so a shape keeps >= 1.6 (8 eps at the
coarsest full level) from its periodic image; the topology of every point is recorded. Start: the
ellipse of perimeter S and area V along x (a start without the circle's symmetry, so the solver does
not stop at the symmetric saddle).

Discretisation: the Fourier spectral grid (Section 5) with the Newton-Krylov backend, exact
constraints. Why not FD: at fixed eps/h the FD profile error is O((h/eps)^2), a constant of the whole
eps sequence that no eps -> 0 extrapolation removes (measured with IPOPT on FD at eps = 0.2,
nu = 0.8: eps/h = 3.2, 6.4, 9.6 give 1.794643, 1.800067, 1.801061, i.e. 7e-3 below the h -> 0
limit; the FD run's extrapolations missed the elastica by 1.2e-3 ... 7.1e-3). The tanh profile's
Fourier spectrum decays like exp(-pi k eps / sqrt 2) (k the angular wavenumber), exp(-6.98 eps/h) at
the Nyquist wavenumber pi/h, so the spectral grid error at eps/h = 3.2 is below 1e-9: the study
measures it (``GRID_CHECK``: the same point at eps/h = 6.4, rows with ``role = grid_check``).

Tolerance per level (``tol_for``): the certificate refuses a result whose round-off floor of the L2
KKT residual (``nk.solve.l2_floor``, ~ eps_mach eps k_max^4 over the residual's scale) reaches tol;
at fixed eps/h that floor grows like eps^-3 (measured 2.2e-10, 1.9e-9, 1.6e-8 at eps = 0.2, 0.1,
0.05, eps/h = 3.2) and like (eps/h)^4 at fixed eps (3.4e-9 at eps = 0.2, eps/h = 6.4), so
tol = 1e-8 max(1, (0.1/eps)^3 (eps/h / 3.2)^4) keeps tol >= 5x the floor. The energy error this allows is
second order in the KKT residual plus lambda . c with |c| <= 0.1 tol (the NK exact stop): below
1e-6 in the reduced energy at every level.

Each point must be certified (``converged``) and a ``minimum`` by the second-order check; a case
whose points are not all so gets no extrapolation (``status`` says why). Reduced energy =
E / (rigidity * sphere_energy(S, 2)) -> integral kappa^2 ds / (4 pi^2 / S), the elastica's e.

Outputs: ``sharp_limit.csv`` (one row per (nu, eps) and per grid check, resumable),
``sharp_limit_summary.csv`` (per nu: reference, energies, the observed order p of the free-order
Richardson fit through the three finest levels (metrics.richardson) and its extrapolation (the
headline ``extrapolated``, ``distance``), the order fitted by np.polyfit to log|e(eps_k) -
e(eps_k+1)| against log eps_k over all levels (``polyfit_order``), the fixed-order p = 2
extrapolation of the two finest, the polynomial extrapolation E = e + a eps + b eps^2 through the
three finest, their distances, and the grid check), and ``sharp_limit.png``. Full: nu = 0.95, 0.9,
0.8, 0.7, 0.6 at eps = 0.2, 0.141421, 0.1, 0.070711, 0.05 (eps/h = 3.2, grids 96 x 64 ... 384 x 256;
eps = 0.025 at 768 x 512 did not finish one point in 15 min on the loaded machine), grid check at
nu = 0.8, eps = 0.2 and 0.1. Quick: nu = 0.8 at eps = 0.6, 0.3, 0.15 (eps/h = 3, 30 x 20 ...
120 x 80): the plumbing and the monotone approach to the reference, in seconds.
"""

from __future__ import annotations

import logging

import csv
import math
import warnings
from pathlib import Path

import numpy as np
from scipy import optimize
from scipy.special import ellipe

from vesicle_opt.api import solve
from vesicle_opt.nk.setup import prepare
from vesicle_opt.scene import from_dict
from vesicle_opt.sharp import elastica
from vesicle_opt.studies._common import column, plt, savefig
from vesicle_opt.studies.runner import run_into
from vesicle_opt.verify import lobpcg
from vesicle_opt.verify.metrics import richardson, richardson_fixed

log = logging.getLogger(__name__)  # the study's lines (the CLI shows INFO; -q hides them)

NAME = "sharp_limit"
PERIMETER = 3 * math.pi
BOX = [[-3.0, 3.0], [-2.0, 2.0]]
NUS = (0.95, 0.9, 0.8, 0.7, 0.6)
FULL = {"epsilons": tuple(round(0.2 * 2 ** (-k / 2), 6) for k in range(5)), "eps_over_h": 3.2}  # 0.2 ... 0.05, ratio sqrt 2
QUICK = {"nus": (0.8,), "epsilons": (0.6, 0.3, 0.15), "eps_over_h": 3.0}
# (nu, eps, eps/h): the same point on a finer grid, against the sequence's eps/h (grid error << eps error)
GRID_CHECK = {"full": ((0.8, 0.2, 6.4), (0.8, 0.1, 6.4)), "quick": ()}
MESH = "spectral"
# an undecided second-order check (LOBPCG at its cap of 300 iterations a level with an error bound above
# mu_min: measured at nu = 0.7, 0.6, eps = 0.05, 384 x 256) is run again with this cap (nu = 0.7: decided,
# a minimum, after 252 iterations)
RECHECK_MAX_ITER = 1000
BACKEND = "newton-krylov"
COLUMNS = ["nu", "epsilon", "n", "h", "eps_over_h", "reduced_energy", "reduced_volume", "area_measured",
           "reference_energy", "error_vs_reference", "converged", "second_order",
           "second_order_min_eigenvalue", "topology", "kkt_residual", "iterations", "wall_time_s", "status",
           "role", "mesh", "backend", "tol", "kkt_floor", "second_order_max_iter"]


def tol_for(eps: float, eps_over_h: float = 3.2) -> float:
    """The solver tolerance of a level: 1e-8, raised like eps^-3 (eps/h)^4 beyond eps = 0.1,
    eps/h = 3.2 so that it stays >= 5x the round-off floor of the spectral KKT residual (module
    docstring; the floor ~ eps k_max^4 over the residual's scale, k_max = pi (eps/h) / eps)."""
    return 1e-8 * max(1.0, (0.1 / eps) ** 3 * (eps_over_h / 3.2) ** 4)


def ellipse_axes(nu: float, perimeter: float) -> tuple[float, float]:
    """Semi-axes (a >= b) of the ellipse with this perimeter and reduced area nu (exact perimeter
    4 a E(1 - b^2/a^2) by scipy's complete elliptic integral)."""
    area = nu * perimeter**2 / (4 * math.pi)

    def per(a):
        b = area / (math.pi * a)
        return 4 * a * ellipe(1 - (b / a) ** 2) - perimeter

    r = math.sqrt(area / math.pi)
    a = optimize.brentq(per, r * (1 + 1e-12), 10 * r)
    return a, area / (math.pi * a)


def scene_raw(nu: float, eps: float, eps_over_h: float) -> dict:
    Lx, Ly = (hi - lo for lo, hi in BOX)
    # one spacing on both axes (the box is 3:2) and even sides: n_y the multiple of 4 nearest Ly / h
    n_y = 4 * max(1, int(round(Ly * eps_over_h / eps / 4)))
    n = [n_y * 3 // 2, n_y]
    assert abs(Lx / n[0] - Ly / n[1]) < 1e-12 * Lx, (BOX, n)
    a, b = ellipse_axes(nu, PERIMETER)
    return {"domain": {"box": BOX, "boundary": "periodic"}, "mesh": {"kind": MESH, "n": n},
            "model": {"epsilon": eps}, "constraints": {"reduced_volume": nu, "area": PERIMETER},
            "initial": {"shape": "ellipse", "semi_axes": [a, b]},
            "solver": {"method": "exact", "tol": tol_for(eps, eps_over_h), "backend": BACKEND, "max_iter": 500}}


def cases(quick: bool) -> list[dict]:
    """One case per (nu, eps), so each point's row is appended as soon as it is solved; then the
    grid checks (role ``grid_check``)."""
    cfg = QUICK if quick else FULL
    nus = QUICK["nus"] if quick else NUS
    seq = [{"case": f"nu{nu:g}-eps{eps:g}", "nu": nu, "epsilon": eps, "eps_over_h": cfg["eps_over_h"],
            "role": "sequence"} for nu in nus for eps in cfg["epsilons"]]
    grid = [{"case": f"nu{nu:g}-eps{eps:g}-r{r:g}", "nu": nu, "epsilon": eps, "eps_over_h": r,
             "role": "grid_check"} for nu, eps, r in GRID_CHECK["quick" if quick else "full"]]
    return seq + grid


def run(case: dict) -> list[dict]:
    nu, eps = case["nu"], case["epsilon"]
    ref = elastica.solve(nu, 24).reduced_energy
    raw = scene_raw(nu, eps, case["eps_over_h"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # near-bound warnings do not apply here; verdicts are recorded
        res = solve(from_dict(raw, name=f"{NAME}-nu{nu:g}-eps{eps:g}"))
    ex = dict(res.extra)
    ex["second_order_max_iter"] = lobpcg.MAX_ITER
    if res.converged and ex.get("second_order") == "not checked":
        sc = from_dict(raw, name=f"{NAME}-nu{nu:g}-eps{eps:g}")
        # only the translations excluded (the exact null modes), as in the front door's own check
        so = lobpcg.check(sc, res, prepare(sc), max_iter=RECHECK_MAX_ITER)
        ex.update(second_order=so.verdict, second_order_min_eigenvalue=so.relative_min_eigenvalue,
                  second_order_max_iter=RECHECK_MAX_ITER)
    h = (BOX[0][1] - BOX[0][0]) / raw["mesh"]["n"][0]
    e = ex.get("reduced_energy", math.nan)
    return [{"nu": nu, "epsilon": eps, "n": "x".join(map(str, raw["mesh"]["n"])), "h": h,
             "eps_over_h": eps / h, "reduced_energy": e, "reduced_volume": ex.get("reduced_volume"),
             "area_measured": ex.get("area"), "reference_energy": ref, "error_vs_reference": e - ref,
             "converged": res.converged, "second_order": ex.get("second_order"),
             "second_order_min_eigenvalue": ex.get("second_order_min_eigenvalue"),
             "topology": ex.get("topology"), "kkt_residual": res.kkt_residual,
             "iterations": res.iterations, "wall_time_s": res.wall_time_s,
             "energy": res.energy, "status": res.outcome, "role": case.get("role", "sequence"),
             "mesh": raw["mesh"]["kind"], "backend": raw["solver"]["backend"], "tol": raw["solver"]["tol"],
             "kkt_floor": ex.get("kkt_l2_floor"), "second_order_max_iter": ex["second_order_max_iter"]}]


def polyfit_order(eps: np.ndarray, e: np.ndarray) -> float:
    """The slope of log|e_k - e_{k+1}| against log eps_k (np.polyfit, degree 1) over all successive
    levels: the observed order in eps (nan with fewer than two differences)."""
    d = np.abs(np.diff(e))
    if len(d) < 2 or not np.all(d > 0):
        return math.nan
    return float(np.polyfit(np.log(eps[:-1]), np.log(d), 1)[0])


def grid_checks(rows: list[dict]) -> dict:
    """(nu, eps) -> (eps/h of the check, e at the check minus e of the sequence's point)."""
    seq = {(float(r["nu"]), float(r["epsilon"])): float(r["reduced_energy"]) for r in rows
           if r.get("role", "sequence") in ("sequence", "", None)}
    out = {}
    for r in rows:
        key = (float(r["nu"]), float(r["epsilon"]))
        if r.get("role") == "grid_check" and key in seq:
            out[key] = (float(r["eps_over_h"]), float(r["reduced_energy"]) - seq[key])
    return out


# the verdicts a sharp-limit point may carry: a minimum, or "marginal" (the least eigenvalue zero
# within its bound: on fine Fourier grids the rotation in the periodic box is flat, |mu| ~ 3e-7
# mu_ref at eps 0.15, while the elastica is a minimum modulo rotations); never a saddle
ACCEPTED = ("minimum", "marginal")


def _certified(row: dict) -> bool:
    return str(row["converged"]) == "True" and row["second_order"] in ACCEPTED


def summarise(rows: list[dict]) -> list[dict]:
    """Per nu: the free-order Richardson limit and order (three finest eps), the polyfit order over
    all levels, the p = 2 extrapolation of the two finest, the polynomial one, their distances to
    the elastica, and the grid check; nan unless every point is a certified minimum."""
    grid = grid_checks(rows)
    rows = [r for r in rows if r.get("role", "sequence") in ("sequence", "", None)]
    out = []
    for nu in sorted({float(r["nu"]) for r in rows if r.get("nu") not in (None, "")}, reverse=True):
        sel = sorted([r for r in rows if float(r["nu"]) == nu],
                     key=lambda r: -float(r["epsilon"]))
        eps = np.array([float(r["epsilon"]) for r in sel])
        e = np.array([float(r["reduced_energy"]) for r in sel])
        ref = float(sel[0]["reference_energy"])
        ok = all(_certified(r) for r in sel)
        closed = all(r["topology"] == "disk-like" for r in sel)
        e_inf = p = e_p2 = e_12 = p_fit = math.nan
        if len(sel) < 3:
            status = "fewer than three levels"
        elif ok and closed:
            e_inf, p = richardson(eps, e)
            p_fit = polyfit_order(eps, e)
            e_p2 = richardson_fixed(eps, e, 2.0)
            # E = e + a eps + b eps^2 through the three finest points (polynomial extrapolation)
            e_12 = float(np.linalg.solve(np.vander(eps[-3:], 3, increasing=True), e[-3:])[0])
            status = "certified" if math.isfinite(p) else "no Richardson fit (differences not monotone)"
        else:
            status = ("not every point a certified minimum (or marginal)" if not ok
                      else "not every point a closed vesicle (topology)")
        checks = {k: v for k, v in grid.items() if k[0] == nu}
        g_max = max((abs(v[1]) for v in checks.values()), default=math.nan)
        out.append({"nu": nu, "reference_energy": ref,
                    **{f"e_eps{k}": e[k] for k in range(len(e))},
                    **{f"eps{k}": eps[k] for k in range(len(eps))},
                    "observed_order": p, "extrapolated": e_inf, "distance": e_inf - ref,
                    "polyfit_order": p_fit,
                    "extrapolated_p2": e_p2, "distance_p2": e_p2 - ref,
                    "extrapolated_orders12": e_12, "distance_orders12": e_12 - ref,
                    "finest_distance": e[-1] - ref,
                    "finest_change": abs(e[-1] - e[-2]) if len(e) > 1 else math.nan,
                    "grid_check": "; ".join(f"eps {k[1]:g}: eps/h {v[0]:g} moves e by {v[1]:+.2e}"
                                            for k, v in sorted(checks.items())) or "none",
                    "grid_check_max": g_max, "status": status})
    return out


def figure(rows: list[dict], path: Path) -> None:
    pyplot = plt()
    fig, ax = pyplot.subplots(figsize=(6, 4.5))
    rows = [r for r in rows if r.get("role", "sequence") in ("sequence", "", None)]
    for nu in sorted({float(r["nu"]) for r in rows}):
        sel = [r for r in rows if float(r["nu"]) == nu]
        eps, err = column(sel, "epsilon"), np.abs(column(sel, "error_vs_reference"))
        ax.loglog(eps, err, "o-", label=f"nu = {nu:g}")
    ax.set_xlabel("epsilon (h = epsilon / const, Fourier spectral)")
    ax.set_ylabel("|reduced energy - elastica|")
    ax.legend(fontsize=8)
    savefig(fig, path)


def main(out, quick: bool = False, executor=None, workers: int = 1) -> int:
    out, rows, good = run_into(NAME, cases(quick), run, out, executor=executor, workers=workers,
                               extra_columns=COLUMNS)
    summary = summarise(good)
    with open(out / f"{NAME}_summary.csv", "w", newline="") as f:
        w = csv.DictWriter(f, list(summary[0]) if summary else ["nu"], lineterminator="\n", extrasaction="ignore")
        w.writeheader()
        w.writerows(summary)
    for s in summary:
        log.info(f"nu = {s['nu']:g}: elastica {s['reference_energy']:.7f}, extrapolated {s['extrapolated']:.7f} "
                 f"(order {s['observed_order']:.2f}, polyfit order {s['polyfit_order']:.2f}, distance "
                 f"{s['distance']:.2e}; p = 2: {s['distance_p2']:.2e}; orders 1, 2: {s['distance_orders12']:.2e}; "
                 f"finest eps: {s['finest_distance']:.2e}; grid check: {s['grid_check']}) {s['status']}")
    if good:
        figure(good, out / f"{NAME}.png")
    certified = all(_certified(r) for r in good)
    return 0 if good and len(good) == len(rows) and certified else 1
