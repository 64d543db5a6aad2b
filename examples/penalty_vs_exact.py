"""
Penalty (11) against exact constraints (7)-(8)
==============================================

    python examples/penalty_vs_exact.py        # from any directory; a few seconds

The penalty solve at M leaves the constraints violated by O(1/M) and its energy below the exact
one by about ``|lambda|^2 / M`` (Theorem 3.2 to first order: at the penalty minimiser lambda = -M c).
"""

import vesicle_opt as vo


def main(n: int = 48, M: float = 1e3) -> dict:
    scene = vo.load_scene("ellipse-2d", [f"mesh.n={n}", f"solver.M={M}"])
    exact = vo.solve(scene, method="exact")
    out = {"exact": exact}
    for method in ("penalty",):
        out[method] = r = vo.solve(scene, method=method)
        print(f"{method:9s} converged={r.converged} E = {r.energy:.10f} (exact {exact.energy:.10f}, "
              f"gap {r.energy - exact.energy:+.3e}) |A - alpha| = {abs(r.volume_residual):.2e}")
    lam2 = exact.lambda_volume**2 + exact.lambda_area**2
    out["predicted_gap"] = -lam2 / M
    print(f"first-order prediction of the penalty gap -|lambda|^2/M = {-lam2 / M:+.3e}")
    return out


if __name__ == "__main__":
    main()
