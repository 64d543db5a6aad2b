"""
Solve a bundled scene and read the certified Result
===================================================

    python examples/solve_and_read.py          # from any directory; about 1 s

The ellipse-2d scene on a 64^2 FD grid with exact constraints (IPOPT). The printed numbers are
the certificate (see "What a result guarantees" in the theory page): converged, the KKT residual,
the second-order verdict and the physical volume, area and reduced volume (Section 3.1), all
attributes of the Result (``vo.write_result`` writes them to summary.json, ``vo.load`` reads them back).
"""

import vesicle_opt as vo


def main(n: int = 64) -> vo.Result:
    scene = vo.load_scene("ellipse-2d", [f"mesh.n={n}"])   # a bundled scene by name (or a TOML path)
    res = vo.solve(scene)                                    # backend "auto": IPOPT for 2D
    print(f"converged={res.converged} outcome={res.outcome.value} energy={res.energy:.10g}")
    print(f"lambda_volume={res.lambda_volume:.6g} lambda_area={res.lambda_area:.6g} kkt={res.kkt_residual:.2e}")
    print(f"second order: {res.second_order}, topology: {res.topology}")   # the certificate's verdicts
    print(f"volume={res.volume:.6g} area={res.area:.6g} reduced_volume={res.reduced_volume:.4f}")
    return res


def plot(res: vo.Result) -> None:
    """phi on the grid with its zero level (the membrane), in the box's coordinates."""
    import matplotlib.pyplot as plt
    n = res.disc.grid_shape
    (x0, x1), (y0, y1) = res.disc.box
    phi = res.phi.reshape(n)
    fig, ax = plt.subplots(figsize=(4.5, 4))
    im = ax.imshow(phi.T, origin="lower", extent=(x0, x1, y0, y1), cmap="RdBu_r", vmin=-1, vmax=1)
    ax.contour(*[res.disc.nodes[:, k].reshape(n) for k in (0, 1)], phi, levels=[0.0], colors="k")
    ax.set(xlabel="x", ylabel="y", title=f"phi, E = {res.energy:.5f}, reduced volume {res.reduced_volume:.3f}")
    fig.colorbar(im, ax=ax, label="phi")


if __name__ == "__main__":
    plot(main())
