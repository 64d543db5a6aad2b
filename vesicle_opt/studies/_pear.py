"""The pear/prolate crossing at c0 = 2.4 (literature units, c0 = C0 R0) for the ``phase_diagram`` study:
the sharp pear and up-down symmetric branches (``sharp.spontaneous``; eps = 0 rows) and, per eps, the
phase-field branches on interface-refined meridian meshes (``mesh.axisymmetric``, ``mesh.refine =
"interface"``), their crossing per eps (``branch.crossing.crossing``) and its eps -> 0 limit
(``branch.crossing.extrapolate_crossing``: free order through three eps). Published: (v, f) =
(0.746, 0.107), Seifert, Berndl & Lipowsky, Phys. Rev. A 44, 1182 (1991).

Units: the scene's ``model.c0`` is C0 / 2 (the energy (3) tends to (2 sqrt2 / 3) F / kappa with
C0 = 2 c0; docs/guide/axisymmetric.md), so at R0 = 1 (area 4 pi) ``model.c0`` = 1.2 and the summary's
``c0_reduced`` reads 2.4.

Sharp: the symmetric branch is walked down from the c0 = 0 prolate at v = 0.9 (odd modes held at
zero); the pear is reached at v = ``V_KICK`` from it kicked along sin(3 s) (24 modes), walked up in v
and carried up the ladder ``LADDER`` of N, each solve from the previous N's coefficients (its narrow
neck converges only algebraically in N; a cold kick at N >= 48 leaves the shapes, measured).

Phase field: the pear one case per v (``FULL["pear_per_v"]``: an eps-continuation through every eps, a
row at each step, ``chain_rows``; at the finest eps a walk in v did not converge), the prolate one case
per eps (a walk in v). Without ``pear_per_v``, one case per (branch, eps). The first point is SEEDED (column ``seed``) with the tanh
profile of the sharp shape at that v (``io.meridian.phase_field_of``) on a band mesh built about the
sharp meridian (``refine.curve_distance``), and the walk goes on warm-started (the front door re-meshes
where the interface leaves its band). With ``case["chain"]`` (coarser eps, descending) the first point
is an eps-continuation instead: solved at the first of them from the sharp seed, then re-seeded at each
finer eps from the previous solution's phi = 0 curve (``seed_from``: its band mesh and tanh profile at
the new eps), each step's cost in the column ``chain``. The pear walks up in v from the lowest of
``vs``, the prolate down from the highest. A point counts for its branch only if its meridian is that
shape (``form``): a pear is one curve from the axis to the axis, up-down asymmetric (|``asymmetry``| >=
``ASYM_MIN``), called "pinched" where its neck radius is under ``NECK_EPS`` eps (the two interfaces of
a neck narrower than a few eps overlap; docs/guide/axisymmetric.md); a prolate is up-down symmetric
(|asymmetry| < ``ASYM_MIN``). A crossing counts as the pear's (``summary``) where the pears' neck AT
the crossing (linear in v between the pear points; the neck widens with v) is at least NECK_EPS eps;
the others are reported apart (``narrow_neck``). The second-order verdicts are those of the
axisymmetric class only (the meridian's check: axisymmetric perturbations).

Sharp limit: the crossing per N and its N -> infinity limit (``extrapolate_modes``: free order through
the three largest N, error = the limit's shift when the largest N is dropped), and the pear's neck at
the crossing likewise. Measured: docs/guide/axisymmetric.md, "c0 = 2.4".
"""

from __future__ import annotations

import math
import time
import types

import numpy as np

from vesicle_opt.branch.crossing import crossing, extrapolate_crossing
from vesicle_opt.errors import SolverError
from vesicle_opt.io.meridian import meridian_curves, phase_field_of
from vesicle_opt.mesh import discretize, refine
from vesicle_opt.scene import from_dict
from vesicle_opt.sharp import axisymmetric as sharp_sym
from vesicle_opt.sharp import spontaneous as S
from vesicle_opt.studies._meridian import axial_extent, centroid, solve_quiet as _solve_quiet
from vesicle_opt.verify.metrics import richardson
from vesicle_opt.studies._common import num as _num

C0 = 2.4  # literature c0 = C0 R0 (scene model.c0 = C0 / 2 at R0 = 1)
PUBLISHED = (0.746, 0.107)  # SBL 1991, read off their figure (+-0.005 in v, +-0.01 in f)
BRANCHES = ("pear", "prolate_c2.4")  # not "prolate": the c0 = 0 prolate rows of phase_diagram keep their name
# the phase field's v grid: its crossing lies above the sharp one at finite eps (at eps = 0.03 the pear
# lies 0.013 below its sharp f, measured, the prolate above it), so the grid reaches v = 0.77
FULL = {"epsilons": (0.03, 0.02, 0.015, 0.0125, 0.01), "vs": (0.74, 0.75, 0.76), "seed_modes": 48,
        "sharp_vs": (0.734, 0.74, 0.746, 0.752, 0.758), "sharp_modes": 128, "chain": True, "pear_per_v": True,
        "pear_vs": (0.75, 0.76)}
# pear_vs: the per-v pear cases (the crossing lies in [0.75, 0.76] at every eps, measured); at v = 0.74 the
# continuation's first step (eps 0.03, a pinched pear) was refused after one iteration and the cold
# eps = 0.01 solve ran to 500 iterations (702 CPU s for nothing, measured)
# pear_per_v: the pear one case a v, each an eps-continuation through every eps (a row at each step): walked in
# v at eps 0.01 from its first point (v 0.75, 578 CPU s through the chain) the warm pears at 0.76 and 0.74 ran to
# IPOPT's 500 iterations unconverged (630, 655 CPU s), measured; without it, one case a (branch, eps) as the
# prolate's, the pear walked up from its lowest v
# chain: the pear's first point through the coarser eps (at eps = 0.015 through 0.03, 0.02: pears at
# v = 0.75, 0.76, 283-302 CPU-s in all, measured; docs/guide/axisymmetric.md)
V_KICK, KICK = 0.72, 0.3  # the pear is reached here from the symmetric shape + KICK sin(3 s) (24 modes)
LADDER = (24, 32, 48, 64, 96, 128)  # the pear's modes, each solve from the previous N's coefficients
ASYM_MIN = 0.02  # |asymmetry| of a pear: measured 0.10-0.13 on the sharp pears (v = 0.74, 0.76; N = 24 .. 64);
# a symmetric shape's tanh seed on the mirrored mesh: 8e-11 (tests/studies/test_pear.py)
NECK_EPS = 3.0  # a neck of radius < 3 eps is called pinched: there tanh(r / sqrt2 eps) < 0.97 on the axis
WALL = 12.0  # walls this many eps from the seed's sharp shape (as the study's other cases)
MARGIN = 0.1  # and this much more room (R0 units) for the walk's shapes
EPS_OVER_H = 4.0  # the band's spacing: the sphere's f is off 0.39 % at eps / h = 4 (docs/guide/axisymmetric.md)
H0 = 0.12  # about this coarse cell side (levels = log2(H0 / h_fine), rounded)
COLUMNS = ["neck_over_eps", "neck_radius", "asymmetry", "nodes", "cpu_s", "chain"]


def _symmetric_start(n: int) -> np.ndarray:
    ref = sharp_sym.solve(0.9, "prolate", second_order=False)
    a = np.zeros(n)
    a[1:16:2] = ref.a[:8]  # wavenumber 2j there is index 2j - 1 here (as tests/sharp/test_spontaneous.py)
    return a


def sharp_branches(vs, n_modes: int, which=BRANCHES) -> dict:
    """{"prolate_c2.4": [Shape], "pear": [Shape]} (those in ``which``) at the reduced volumes ``vs``,
    ascending (module docstring); the pears at ``n_modes`` (a rung of ``LADDER``; "ladder": {N: the
    pears at every rung up to it}; a rung whose solve fails keeps that failure, not converged, at the
    rungs above), the symmetric shapes at 24 modes (converged there: N = 24, 32, 48, 64 agree to 1e-10
    in f, measured)."""
    vs = sorted(float(v) for v in vs)

    def symmetric(path):
        sym, walk = _symmetric_start(24), {}
        for v in path:
            sol = S.solve(v, C0, sym)
            sym = sol.a.copy()
            sym[0::2] = 0.0
            walk[v] = sol
        return walk

    out = {}
    if "prolate_c2.4" in which:
        walk = symmetric(sorted({0.9, 0.85, 0.8, 0.76, *vs}, reverse=True))
        out["prolate_c2.4"] = [walk[v] for v in vs]
    if "pear" in which:  # the kick from the shape reached along this path: through other points (0.752,
        # 0.746, 0.74, then 0.72) the kicked SLSQP left the shapes (NaN), measured
        kicked = symmetric((0.9, 0.85, 0.8, 0.76, V_KICK))[V_KICK].a.copy()
        kicked[2] = KICK
        out["pear"], out["ladder"] = [], {n: [] for n in LADDER if n <= n_modes}
        for v in sorted({V_KICK, *vs}):
            sol = S.solve(v, C0, kicked)
            kicked = sol.a
            for n in out["ladder"]:
                if n > 24:
                    sol = S.solve(v, C0, sol.a, n) if sol.converged else sol  # a failed rung ends the ladder
                if v in vs:
                    out["ladder"][n].append(sol)
            if v in vs:
                out["pear"].append(sol)
    return out


def measure(r, z) -> tuple[float, float]:
    """(neck radius, asymmetry) of a meridian (r, z) from pole to pole: the neck is the radius at the
    deepest waist (the point whose r lies furthest below the smaller of the largest radii on either
    side of it; nan without one: a convex meridian), the asymmetry the volume centroid's height above
    the middle of [z_min, z_max] over the height (0 for an up-down symmetric shape)."""
    r, z = np.asarray(r, float), np.asarray(z, float)
    height = float(z.max() - z.min())
    return _neck(r), (centroid(r, z) - (z.max() + z.min()) / 2) / height


def _neck(r: np.ndarray) -> float:
    left, right = np.maximum.accumulate(r), np.maximum.accumulate(r[::-1])[::-1]
    depth = np.minimum(left, right) - r
    k = int(np.argmax(depth))
    return float(r[k]) if depth[k] > 1e-3 * r.max() else math.nan


def form(curves, eps: float) -> tuple[str, float, float]:
    """(shape, neck / eps, asymmetry) of a phase field's meridian curves (module docstring): "pear",
    "prolate" (up-down symmetric), "pinched" (a pear's neck under NECK_EPS eps, or two bodies),
    or "other"."""
    if len(curves) != 1 or curves[0][0][0] > 0 or curves[0][-1][0] > 0:
        return ("pinched" if len(curves) == 2 else "other"), math.nan, math.nan
    neck, asym = measure(curves[0][:, 0], curves[0][:, 1])
    if abs(asym) < ASYM_MIN:
        return "prolate", neck / eps, asym
    if math.isfinite(neck) and neck >= NECK_EPS * eps:
        return "pear", neck / eps, asym
    return "pinched", neck / eps, asym


def box_of(r, z, eps: float):
    """(box, n, levels) of the meridian mesh about a sharp meridian: square cells of side h_fine
    2^levels with h_fine = eps / EPS_OVER_H, the walls WALL eps + MARGIN from the shape, the box
    centred at its volume centroid with an even n_z (the mesh mirrors about the box's mid-height,
    where the solve's axial pin holds the centre of mass: a pear centred at its mid-height, ~0.3 R0
    from its centroid, fell to the symmetric shape in IPOPT's first steps at eps = 0.03 and 0.015,
    measured; ``mesh.band_start.centred``)."""
    h_fine = eps / EPS_OVER_H
    levels = max(1, round(math.log2(H0 / h_fine)))
    h0 = h_fine * 2**levels
    pad = WALL * eps + MARGIN
    nr = math.ceil((float(np.max(r)) + pad) / h0)
    zc, ext = axial_extent([(np.asarray(r, float), np.asarray(z, float))])  # as ``_meridian.layout``
    half = math.ceil((ext + pad) / h0)
    return [[0.0, nr * h0], [zc - half * h0, zc + half * h0]], [nr, 2 * half], levels


def _scene(box, n, levels: int, eps: float, v: float, name: str):
    raw = {"domain": {"box": box, "boundary": "natural"},
           "mesh": {"kind": "axisymmetric", "n": n, "refine": "interface", "levels": levels, "band": 8.0},
           "model": {"epsilon": eps, "c0": C0 / 2}, "constraints": {"reduced_volume": v, "area": 4 * math.pi},
           "initial": {"shape": "sphere", "radius": 1.0}, "solver": {"method": "exact"}}
    return from_dict(raw, name=name)


def _row(branch: str, v: float, eps: float, **kw) -> dict:
    return {"branch": branch, "c0": C0, "target_v": v, "epsilon": eps, "kind": "point", "side": "", **kw}


def sharp_case(case: dict) -> list[dict]:
    """eps = 0 rows: both sharp branches at ``case["vs"]`` with ``case["n_modes"]`` pear modes, and
    their crossing (kind ``crossing``) at every rung of ``LADDER`` up to it (the pear's convergence in
    N; a rung with a failed solve has none)."""
    t0 = time.process_time()
    br = sharp_branches(case["vs"], case["n_modes"])
    rows = []
    for b in BRANCHES:
        for s in br[b]:
            neck, asym = measure(*s.meridian(4096)) if s.converged else (math.nan, math.nan)
            rows.append(_row(b, s.v, 0.0, shape="pear" if b == "pear" else "prolate", n=str(s.a.size),
                             reduced_volume=s.v, f=s.f, sharp_f=s.f, c0_reduced=C0, converged=s.converged,
                             kkt_residual=s.kkt_residual, asymmetry=asym, neck_over_eps=math.nan,
                             seed="symmetric shape + 0.3 sin 3s at v = 0.72" if b == "pear" else "c0 = 0 prolate",
                             neck_radius=neck, status=f"neck radius {neck:.5f}"))
    sym = br["prolate_c2.4"]
    for n, pears in br["ladder"].items():
        if not all(q.converged for q in pears):
            continue
        x = crossing([q.v for q in pears], [q.f for q in pears], [q.v for q in sym], [q.f for q in sym])
        if x is not None:  # the neck at the crossing: linear in v between the pears about it
            neck = float(np.interp(x["reduced_volume"], [q.v for q in pears],
                                   [measure(*q.meridian(4096))[0] for q in pears]))
            rows.append(_row("pear", x["reduced_volume"], 0.0, kind="crossing", n=str(n),
                             reduced_volume=x["reduced_volume"], f=x["reduced_energy"], converged=True,
                             neck_radius=neck))
    rows[-1]["cpu_s"] = time.process_time() - t0
    return rows


def _densify(curve: np.ndarray, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """(r, z) of a polyline resampled (linearly) at most ``spacing`` apart: ``phase_field_of`` measures
    the distance to the vertices, so the seed's profile is the polyline's to spacing / 2."""
    seg = np.linalg.norm(np.diff(curve, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, s[-1], max(2, math.ceil(s[-1] / spacing) + 1))
    return np.interp(t, s, curve[:, 0]), np.interp(t, s, curve[:, 1])


def seed_from(res, eps: float):
    """An eps-continuation's seed at ``eps`` from a coarser eps's solution ``res``: its phi = 0 curve
    (one curve from the axis to the axis, densified) as the sharp curve of the band mesh and of the
    tanh profile at the new eps (module docstring): its (r, z), or None when the solution's meridian
    is not one such curve."""
    curves = meridian_curves(res.disc, res.phi)
    if len(curves) != 1 or curves[0][0][0] > 0 or curves[0][-1][0] > 0:
        return None
    return _densify(curves[0], eps / EPS_OVER_H / 8)


def _first(case: dict, which: str, v: float, r, z, keep: list | None = None):
    """The first point's (box, n, levels, start, seed text, chain text): seeded at ``case["epsilon"]``
    with the sharp shape (r, z), or, with ``case["chain"]`` (coarser eps, descending), solved at the
    first of them from the sharp shape and carried down the chain by ``seed_from``, each step's
    CPU-s and IPOPT iterations in the chain text (the last step's solve is the case's first point).
    ``keep``: a list that gets (eps, Result, n, CPU-s) of each chain step (``chain_case``)."""
    eps, steps, notes = case["epsilon"], [*case.get("chain", ()), case["epsilon"]], []
    for k, e in enumerate(steps):
        box, n, levels = box_of(r, z, e)
        disc = discretize(_scene(box, n, levels, e, v, "seed"), interface=refine.curve_distance(
            np.column_stack([r, z]), e / EPS_OVER_H))
        start = types.SimpleNamespace(disc=disc, phi=phase_field_of(r, z, disc.nodes, e))
        if e == eps:
            break
        c1 = time.process_time()
        res = _solve_quiet(_scene(box, n, levels, e, v, f"phase_diagram-{which}-v{v:g}-eps{e:g}-chain"), start)
        shape = form(meridian_curves(res.disc, res.phi), e)[0] if res.converged else "failed"
        notes.append(f"eps {e:g}: {time.process_time() - c1:.1f} CPU-s, {res.iterations} it, {shape}")
        if keep is not None:
            keep.append((e, res, n, time.process_time() - c1))
        nxt = seed_from(res, steps[k + 1]) if res.converged else None
        if nxt is None:  # the chain broke: the sharp seed at eps (a cold start), said so
            notes.append("chain broken: sharp seed")
            box, n, levels = box_of(r, z, eps)
            disc = discretize(_scene(box, n, levels, eps, v, "seed"), interface=refine.curve_distance(
                np.column_stack([r, z]), eps / EPS_OVER_H))
            start = types.SimpleNamespace(disc=disc, phi=phase_field_of(r, z, disc.nodes, eps))
            break
        r, z = nxt
    seed = f"sharp {which} at v = {v:g} ({case['n_modes']} modes; a seed)"
    if case.get("chain") and "chain broken: sharp seed" not in notes:
        seed = f"eps-continuation {' -> '.join(f'{e:g}' for e in steps)} from the " + seed
    return box, n, levels, start, seed, "; ".join(notes)


def phase_case(case: dict) -> list[dict]:
    """One phase-field branch at one eps (module docstring): the seeded first point (``_first``: from
    the sharp shape, or through the eps-continuation ``case["chain"]``), then the walk."""
    eps, which, t0 = case["epsilon"], case["branch"], time.process_time()
    vs = sorted(case["vs"], reverse=which != "pear")
    grid = sorted({*vs, *case.get("ref_vs", ())})  # the sharp path: its SLSQP solves depend on the steps
    ref = dict(zip(grid, sharp_branches(grid, case["n_modes"], (which,))[which]))  # (ascending v)
    ref = [ref[v] for v in vs]
    if not ref[0].converged:  # no seed (e.g. the kicked SLSQP left the shapes): said so, not meshed on NaN
        raise SolverError(f"the sharp {which} seed at v = {vs[0]:g} did not converge ({case['n_modes']} modes)")
    steps: list | None = [] if case.get("chain_rows") else None
    box, n, levels, start, seed, chain = _first(case, which, vs[0], *ref[0].meridian(4096), keep=steps)
    rows = [_point(which, vs[0], e, res, ref[0].f, m, f"eps-continuation step from the sharp {which} "
                   f"({case['n_modes']} modes; a seed)", "up", cpu, chain) for e, res, m, cpu in steps or ()]
    for v, s in zip(vs, ref):
        sc = _scene(box, n, levels, eps, v, f"phase_diagram-{which}-v{v:g}-eps{eps:g}")
        c1 = time.process_time()
        res = _solve_quiet(sc, start)
        rows.append(_point(which, v, eps, res, s.f, n, seed, "up" if which == "pear" else "down",
                           time.process_time() - c1, chain))
        if not res.converged:
            break
        start, seed, chain = res, "previous point", ""
    rows[0]["cpu_s"] = _num(rows[0]["cpu_s"]) + (time.process_time() - t0 - sum(_num(q["cpu_s"]) for q in rows))
    return rows


def _point(which: str, v: float, eps: float, res, sharp_f: float, n, seed: str, walk: str, cpu: float,
           chain: str) -> dict:
    """A phase-field row of one solve: f against the sharp one, the verdicts, the meridian's form."""
    ex = res.extra
    shape, neck, asym = form(meridian_curves(res.disc, res.phi), eps) if res.converged else (None, math.nan, math.nan)
    f = _num(ex.get("f"))
    return _row(which, v, eps, shape=shape, n="x".join(map(str, n)), h=eps / EPS_OVER_H, f=f,
                c0_reduced=ex.get("c0_reduced"), reduced_volume=ex.get("reduced_volume"), sharp_f=sharp_f,
                f_minus_sharp=f - sharp_f, converged=res.converged, second_order=ex.get("second_order"),
                second_order_min_eigenvalue=ex.get("second_order_min_eigenvalue"),
                topology=ex.get("topology"), kkt_residual=res.kkt_residual, iterations=res.iterations,
                wall_time_s=res.wall_time_s, seed=seed, status=res.outcome, walk=walk, neck_over_eps=neck,
                neck_radius=neck * eps, asymmetry=asym, nodes=res.disc.n_nodes, cpu_s=cpu, chain=chain)


def run(case: dict) -> list[dict]:
    return sharp_case(case) if case["epsilon"] == 0 else phase_case(case)


def cases(quick: bool = False, cfg: dict | None = None) -> list[dict]:
    """The sharp case and one case per (branch, eps) of ``cfg`` (default ``FULL``), the finest eps
    first (the longest: the pool takes the cases in order), the pear's with ``chain`` (every coarser
    eps) where ``cfg["chain"]``; none in the quick run (``phase_diagram``'s
    extension hook: its quick run is the c0 = 0 plumbing)."""
    if quick:
        return []
    cfg = cfg or FULL
    out = [{"case": "pear-sharp", "branch": "pear", "epsilon": 0.0, "vs": list(cfg["sharp_vs"]),
            "n_modes": cfg["sharp_modes"]}]
    per_v = cfg.get("pear_per_v")
    if per_v:  # the longest cases first: the chain through every eps, a row at each (``chain_rows``)
        out += [{"case": f"pear-v{v:g}", "branch": "pear", "epsilon": min(cfg["epsilons"]), "vs": [v],
                 "n_modes": cfg["seed_modes"], "chain": sorted(cfg["epsilons"], reverse=True)[:-1],
                 "chain_rows": True, "ref_vs": list(cfg["vs"])} for v in cfg.get("pear_vs", cfg["vs"])]
    for eps in sorted(cfg["epsilons"]):
        out += [{"case": f"{b}-eps{eps:g}", "branch": b, "epsilon": eps, "vs": list(cfg["vs"]),
                 "n_modes": cfg["seed_modes"]} for b in BRANCHES if not (per_v and b == "pear")]
        if per_v:
            continue
        coarser = sorted((e for e in cfg["epsilons"] if e > eps), reverse=True)
        if cfg.get("chain") and coarser:  # the pear's first point through the coarser eps (``_first``)
            out[-2]["chain"] = coarser
    return out


def _per_eps(rows: list[dict]) -> dict:
    """{eps: crossing} of the certified prolates and one-curve asymmetric pears (shape "pear", or
    "pinched" with a neck: not two bodies), each crossing with ``neck_over_eps``: the pears' neck / eps
    linear in v at the crossing (nan without necks)."""
    ok = [r for r in rows if r.get("branch") in BRANCHES and str(r.get("converged")) == "True"
          and str(r.get("kind", "point")) == "point" and _num(r.get("epsilon")) > 0
          and (r.get("shape") == "pear" or (r.get("shape") == "pinched" and math.isfinite(_num(r.get("neck_over_eps"))))
               if r["branch"] == "pear" else r.get("shape") == "prolate")]
    per_eps = {}
    for eps in sorted({_num(r["epsilon"]) for r in ok}, reverse=True):
        sel = [sorted([r for r in ok if _num(r["epsilon"]) == eps and r["branch"] == b],
                      key=lambda r: _num(r["reduced_volume"])) for b in BRANCHES]
        x = crossing(*[[_num(r[k]) for r in q] for q in sel for k in ("reduced_volume", "f")])
        if x is not None:
            pv, pn = [_num(r["reduced_volume"]) for r in sel[0]], [_num(r.get("neck_over_eps")) for r in sel[0]]
            per_eps[eps] = {**x, "neck_over_eps": float(np.interp(x["reduced_volume"], pv, pn))}
    return per_eps


def extrapolate_modes(per_modes: dict) -> dict:
    """N -> infinity of the sharp crossing from {N: {"v", "f"[, "neck_radius"]}} (the ladder's rungs):
    y = y_inf + C N^-p through the three largest N (``metrics.richardson`` with h = 1/N, free order
    ``order_*``), its stated error ``error_*`` = the shift of y_inf when the largest N is dropped
    (the same fit through the three before it; nan with fewer than four rungs), and ``correction_*``
    = y_inf - y(largest N). nan where no order in [0.25, 8] fits."""
    pm = {int(n): x for n, x in per_modes.items()}
    ns = sorted(pm)
    out = {"n_modes": ns}
    h = 1.0 / np.array(ns, float)
    for key in ("v", "f", "neck_radius"):
        y = np.array([_num(pm[n].get(key)) for n in ns])
        y_inf, p = richardson(h, y) if len(ns) >= 3 else (math.nan, math.nan)
        prev = richardson(h[:-1], y[:-1])[0] if len(ns) >= 4 else math.nan
        out[key], out["order_" + key] = y_inf, p
        out["error_" + key] = abs(y_inf - prev)
        out["correction_" + key] = y_inf - y[-1]
    return out


def _plain(per_eps: dict) -> dict:
    return {f"{e:g}": {"v": x["reduced_volume"], "f": x["reduced_energy"], "neck_over_eps": x["neck_over_eps"]}
            for e, x in per_eps.items()}


def _extrapolated(per_eps: dict) -> dict:
    """``extrapolate_crossing`` and the same free-order fit of the pears' neck radius at the crossing."""
    out = extrapolate_crossing(per_eps)
    necks = {e: {"reduced_volume": x["neck_over_eps"] * e, "reduced_energy": math.nan} for e, x in per_eps.items()}
    n = extrapolate_crossing(necks)
    out["neck_radius_richardson"], out["order_neck_radius"] = n["reduced_volume_richardson"], n["order_reduced_volume"]
    return out


def summary(rows: list[dict]) -> dict:
    """``pear_prolate_crossing``: per eps the crossing of the certified prolates and one-curve pears
    whose neck at the crossing (linear in v between the pear points) is at least NECK_EPS eps, its
    eps -> 0 limit (free order through three eps, p = 2 through the finest two), the sharp crossing
    (eps = 0 rows of kind crossing: the most modes, per N, and its N -> infinity limit with its order
    and stated error, ``extrapolate_modes``) and the published value; ``narrow_neck``: the same with
    every one-curve pear whatever its neck (the crossings whose pears' neck is under NECK_EPS eps
    counted too), for comparison: their neck is narrower than the interface resolves."""
    every = _per_eps(rows)
    per_eps = {e: x for e, x in every.items() if x["neck_over_eps"] >= NECK_EPS}
    out = {"per_eps": _plain(per_eps), "published": {"v": PUBLISHED[0], "f": PUBLISHED[1]}}
    if len(per_eps) >= 2:
        out["extrapolated"] = _extrapolated(per_eps)
    out["narrow_neck"] = {"per_eps": _plain(every)}
    if len(every) >= 2:
        out["narrow_neck"]["extrapolated"] = _extrapolated(every)
    sharp_rows = sorted([r for r in rows if r.get("branch") in BRANCHES and r.get("kind") == "crossing"],
                        key=lambda r: _num(r.get("n")))
    if sharp_rows:  # the most modes; every rung (the pear's convergence in N); N -> infinity
        out["sharp"] = {"v": _num(sharp_rows[-1]["reduced_volume"]), "f": _num(sharp_rows[-1]["f"]),
                        "n_modes": int(_num(sharp_rows[-1].get("n")))}
        out["sharp_per_modes"] = {str(int(_num(r.get("n")))): {"v": _num(r["reduced_volume"]), "f": _num(r["f"]),
                                                            "neck_radius": _num(r.get("neck_radius"))}
                                  for r in sharp_rows}
        out["sharp_extrapolated"] = extrapolate_modes(out["sharp_per_modes"])
    return {"pear_prolate_crossing": out}
