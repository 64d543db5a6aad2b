"""
Build the CasADi NLP and add a constraint of one's own
======================================================

    python examples/own_constraint.py          # from any directory; about 1 s

``vo.build_nlp(scene).as_dict()`` is a plain {"x", "f", "g", "p"} NLP of CasADi MX expressions.
Here we add one row: the centre of mass of the inside, sum_i m_i x_i (1 + phi_i) / 2 over the
volume, is pinned at x = 0.5 (the shape may not sit at the box centre), and solve with
``casadi.nlpsol`` directly. The added row is then checked on the solution.
"""

import casadi as ca
import numpy as np

import vesicle_opt as vo


def main(n: int = 32, x_center: float = 0.5) -> float:
    scene = vo.load_scene("ellipse-2d", [f"mesh.n={n}"])
    nlp = vo.build_nlp(scene)
    d = nlp.as_dict()
    phi = d["x"][: nlp.disc.n_nodes]                      # lumped FD: the unknowns are phi
    m, x = nlp.disc.weights, nlp.disc.nodes[:, 0]
    inside = ca.dot(ca.DM(m), (1 + phi) / 2)              # enclosed volume (|Omega| + A) / 2
    moment = ca.dot(ca.DM(m * x), (1 + phi) / 2)
    g = ca.vertcat(d["g"], moment - x_center * inside)    # our row: centre of mass at x_center
    solver = ca.nlpsol("own", "ipopt", {**d, "g": g}, {"ipopt.print_level": 0, "print_time": False,
                                                      "ipopt.tol": 1e-8, "ipopt.sb": "yes"})
    sol = solver(x0=nlp.x0, lbx=nlp.lbx, ubx=nlp.ubx, lbg=np.append(nlp.lbg, 0.0), ubg=np.append(nlp.ubg, 0.0))
    phi_opt = np.asarray(sol["x"]).ravel()[: nlp.disc.n_nodes]
    w = m * (1 + phi_opt) / 2
    centre = float(w @ x / w.sum())
    print(f"IPOPT: {solver.stats()['return_status']}, centre of mass x = {centre:.8f} (asked {x_center})")
    return centre


if __name__ == "__main__":
    main()
