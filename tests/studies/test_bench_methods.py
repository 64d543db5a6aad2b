"""The bench_methods study: its aggregation (medians, ratios, differences, the same-point test and
the interleaved order) on made-up runs, one real scene through whole CLI processes, and --quick."""

import csv
import math
import warnings

import pytest

from vesicle_opt.studies import bench_methods as bm


def _run(exit_code, wall, **summary):
    return {"exit": exit_code, "wall": wall, "load": 1.0, "summary": summary, "stderr": ""}


def test_rows_take_medians_ratios_and_tell_another_point():
    E = 10.0
    runs = {"exact": [_run(0, w, energy=E, converged=True, outcome="converged") for w in (4.0, 9.0, 5.0)],
            "penalty": [_run(1, 2.0, energy=9.99, converged=False, outcome="roundoff_floor")] * 3,
            "continuation": [_run(0, w, energy=9.99, energy_extrapolated=E * (1 + 3e-9), polish_energy=E * (1 + 1e-9),
                                  converged=True, outcome="converged") for w in (8.0, 11.0, 12.0)],
            "augmented": [_run(0, 3.0, energy=E * (1 - 1e-3), converged=True, outcome="converged")] * 3}
    rows = {r["method"]: r for r in bm.rows_of("s", runs)}
    assert rows["exact"]["wall_median"] == 5.0 and rows["exact"]["ratio_vs_exact"] == 1.0
    assert rows["exact"]["wall_runs"] == "4.000 9.000 5.000" and rows["exact"]["same_point"] is True
    assert rows["penalty"]["exit"] == 1 and rows["penalty"]["same_point"] is None  # no exact-constraint point
    c = rows["continuation"]
    assert c["ratio_vs_exact"] == pytest.approx(11.0 / 5.0, rel=1e-15) and c["compared"] == "energy_extrapolated"
    assert c["rel_diff_vs_exact"] == pytest.approx(3e-9, rel=1e-6)  # the extrapolated value, not the stage's
    assert c["same_point"] is True and c["within_target"] is False  # 2.2x > 2x: the target fails
    a = rows["augmented"]  # 1e-3 lower: another KKT point, so no verdict on the 2x target
    assert a["same_point"] is False and a["within_target"] is None and a["ratio_vs_exact"] == 0.6
    # a failed exact run leaves nothing to compare with
    runs["exact"][1] = _run(1, 4.0, energy=E, converged=False)
    assert all(math.isnan(r["rel_diff_vs_exact"]) for r in bm.rows_of("s", runs))


def test_a_method_on_another_point_is_judged_against_exact_escape_where_it_ends_there():
    """The torus case: exact ends on a saddle (330.53), continuation and augmented on a lower minimum
    (330.20) that exact_escape reaches too; their 2x is judged against exact_escape, not exact."""
    sad, low = 330.5325, 330.1976
    runs = {"exact": [_run(0, 10.0, energy=sad, converged=True, second_order="saddle")],
            "continuation": [_run(0, 29.0, energy=low - 1e-3, energy_extrapolated=low, polish_energy=low,
                                  converged=True)],
            "augmented": [_run(0, 45.0, energy=low * (1 + 1e-9), converged=True)],
            bm.ESCAPE: [_run(0, 20.0, energy=low, converged=True, escape_rounds=1, second_order="minimum")]}
    rows = {r["method"]: r for r in bm.rows_of("torus", runs)}
    c, a = rows["continuation"], rows["augmented"]
    assert c["same_point"] is False and c["ratio_vs_exact"] == 2.9  # another point than exact's
    assert c["reference"] == bm.ESCAPE and c["ratio_vs_reference"] == 29.0 / 20.0 and c["within_target"] is True
    assert c["rel_diff_vs_reference"] == 0.0 and c["rel_diff_vs_exact"] > 1e-3  # its extrapolation: the minimum's
    assert a["reference"] == bm.ESCAPE and a["ratio_vs_reference"] == 45.0 / 20.0 and a["within_target"] is False
    assert rows[bm.ESCAPE]["escape_rounds"] == 1 and rows[bm.ESCAPE]["reference"] is None
    # an escape that reaches yet another point is no reference
    runs[bm.ESCAPE] = [_run(0, 20.0, energy=low - 0.5, converged=True, escape_rounds=1)]
    assert all(r["reference"] is None and r["within_target"] is None for r in bm.rows_of("torus", runs))
    # exact_escape joins the methods on the escape scenes only, and only where exact runs
    cs = {c["scene"]: c["methods"] for c in bm.cases(False, scenes=["torus-table1-3d", "ellipse-2d"])}
    assert cs["torus-table1-3d"] == bm.METHODS + (bm.ESCAPE,) and cs["ellipse-2d"] == bm.METHODS
    assert bm.cases(False, scenes=["torus-table1-3d"], methods=("continuation",))[0]["methods"] == ("continuation",)


def test_exact_escape_leaves_a_saddle_for_a_certified_minimum():
    """ellipse-2d on 48^2 FD: exact ends on the symmetric saddle (E 2.688239, the issue's), one push along
    the check's least eigenvector and an exact solve reach a lower point that the second-order check
    certifies a minimum (measured E 2.685772, mu_min +0.169 mu_ref; 1.6 s CPU)."""
    from vesicle_opt.scene import load
    from vesicle_opt.studies._escape import solve_escaping
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # eps / h below the recommended 2 on 48^2: the case
        r, energies, k = solve_escaping(load("ellipse-2d", ["mesh.n=48"]))
    assert k == 1 and energies[0] == pytest.approx(2.688239328, rel=1e-8)  # the saddle (5e-12 apart)
    assert r.converged and r.extra["second_order"] == "minimum" and r.energy < energies[0] - 1e-3


def test_rounds_rotate_the_order_and_a_timeout_is_the_worst_exit():
    seen = []
    bm.interleaved("s", ("a", "b", "c"), 3, run=lambda sc, m: seen.append(m) or _run(0, 1.0))
    assert seen == ["a", "b", "c", "b", "c", "a", "c", "a", "b"]
    assert bm._worst([0, "timeout", 1]) == "timeout" and bm._worst([0, 2, 1]) == 2


def test_one_scene_in_whole_processes(tmp_path):
    """elastica-2d (64^2 FD, ~1 s a solve): exact and continuation as the CLI runs them; the
    extrapolated energy lands on exact's (measured 1.2e-11 relative; the 1e-8 target)."""
    code = bm.main(tmp_path, scenes=["elastica-2d"], methods=("exact", "continuation"), repeats=1)
    rows = {r["method"]: r for r in csv.DictReader((tmp_path / "bench_methods.csv").open())}
    assert code == 0 and set(rows) == {"exact", "continuation"}
    assert all(r["exit"] == "0" and r["outcome"] == "converged" for r in rows.values())
    c = rows["continuation"]
    assert float(c["rel_diff_vs_exact"]) < bm.TARGET_EXTRAPOLATION and c["same_point"] == "True"
    assert float(c["wall_median"]) > 0 and float(rows["exact"]["ratio_vs_exact"]) == 1.0


@pytest.mark.slow
def test_quick_mode_runs_every_method_on_the_2d_scenes(tmp_path):
    code = bm.main(tmp_path, quick=True)
    rows = list(csv.DictReader((tmp_path / "bench_methods.csv").open()))
    dims = bm.scene_dims()
    assert {r["scene"] for r in rows} == {s for s, d in dims.items() if d == 2}
    assert len(rows) == 4 * len({r["scene"] for r in rows})
    assert all(r["exit"] == "0" for r in rows), [(r["scene"], r["method"], r["exit"]) for r in rows if r["exit"] != "0"]
    cont = {r["scene"]: r for r in rows if r["method"] == "continuation"}
    assert all(r["same_point"] == "True" for r in cont.values())  # M0 = 100: every 2D scene on exact's point
    # the multiplier-corrected extrapolation (model.extrapolation) meets 1e-8 on every 2D scene (measured
    # 8.3e-10 on circle-2d, whose plain Richardson was 7.5e-8; 1.3e-14 ... 8.1e-14 elsewhere)
    for name in cont:
        assert float(cont[name]["rel_diff_vs_exact"]) < bm.TARGET_EXTRAPOLATION, cont[name]
    over = [r for r in rows if r["within_target"] == "False"]  # a comparable ratio above 2x (timing: shared machine)
    assert code == (1 if over else 0), over
