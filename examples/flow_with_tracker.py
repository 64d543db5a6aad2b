"""
A gradient flow (18) with trackers
==================================

    python examples/flow_with_tracker.py       # from any directory; a few seconds

The penalty scheme (18) on a 32^2 grid from the scene's start; the energy law (22) holds at
every step to round-off, which the callback records. The run stops when E falls below 8.
"""

import vesicle_opt as vo
from vesicle_opt.flows.trackers import HistoryTracker, StopTracker


def main(n: int = 32, stop_below: float = 8.0):
    scene = vo.load_scene("ellipse-2d", [f"mesh.n={n}", "solver.M=100", "flow.dt=1e-3", "flow.t_end=0.5"])
    history = HistoryTracker()
    worst = []
    res = vo.flow(scene, trackers=[history, StopTracker(lambda row: row["energy"] < stop_below),
                                   lambda state, row: worst.append(abs(row["energy_law_residual"]))])
    print(f"{res.status.value} after {res.steps} steps at t = {res.t:.4g}: E = {res.energy:.8g}; "
          f"largest energy-law residual {max(worst):.1e}; {len(history.rows)} rows in the history")
    return res, max(worst)


def plot(res) -> None:
    """The energy E_M along the flow: it decreases at every step (the energy law (22))."""
    import matplotlib.pyplot as plt
    rows = res.history
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot([r["t"] for r in rows], [r["energy"] for r in rows], "o-", ms=3)
    ax.set(xlabel="t", ylabel="energy", title=f"penalty flow (18): {res.status.value} after {res.steps} steps")


if __name__ == "__main__":
    plot(main()[0])
