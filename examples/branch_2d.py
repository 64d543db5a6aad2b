"""
A branch of equilibria in the reduced volume (2D elastica)
==========================================================

    python examples/branch_2d.py          # from any directory; a few seconds

A closed vesicle of perimeter S = 8 in a periodic 8 x 8 box (FD 48^2, eps = 0.4, a coarse and
diffuse interface that keeps this example fast), started from an ellipse at reduced area
nu = 0.95 and followed down to nu = 0.85 with exact constraints (IPOPT), each point warm-started
from the previous and certified (KKT, second order, topology). The envelope identity
dE*/dnu = lambda_volume dalpha/dnu + lambda_area dbeta/dnu is checked at every interior point.
"""

import vesicle_opt as vo


def main(n: int = 48, to: float = 0.85, step: float = -0.05, out=None) -> vo.Branch:
    scene = vo.scene.from_dict({
        "domain": {"box": [[-4, 4], [-4, 4]]}, "mesh": {"kind": "fd", "n": n}, "model": {"epsilon": 0.4},
        "constraints": {"reduced_volume": 0.95, "area": 8.0},       # area = the perimeter in 2D
        "initial": {"shape": "ellipse", "semi_axes": [1.45, 1.1]}})
    b = vo.branch(scene, "reduced_volume", to=to, step=step, out=out)  # out=DIR: branch.csv, snapshots, PNG
    for r in b.points():
        print(f"nu = {r['reduced_volume']:.4f}  reduced energy = {r['reduced_energy']:.6f}  "
              f"{r['second_order']}  envelope residual = {r.get('envelope_residual')}")
    return b


def plot(b: vo.Branch) -> None:
    """The energy diagram: reduced energy against reduced area along the branch."""
    import matplotlib.pyplot as plt
    pts = sorted(b.points(), key=lambda r: r["reduced_volume"])
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot([r["reduced_volume"] for r in pts], [r["reduced_energy"] for r in pts], "o-")
    ax.set(xlabel="reduced area", ylabel="E / E_circle", title="2D elastica branch (every point a minimum)")


if __name__ == "__main__":
    plot(main())
