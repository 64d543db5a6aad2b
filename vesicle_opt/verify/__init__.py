"""Checks of a computed result that share no code with the solver that produced it.

* ``kkt``: the relative L2 KKT residual from hand-derived gradients; ``certify``: the one rule that
  decides ``converged`` for every backend and method, and the one ``Result`` builder;
* ``second_order`` (assembled, shift-invert Lanczos) and ``lobpcg`` (matrix-free): minimum or saddle,
  one quantity and one rule (``verdict``);
* ``band``: an interface-refined mesh's band still holds the result's interface (``mesh.refine``);
* ``topology``: components, Euler characteristic, periodic wraps; ``metrics``: error norms, orders;
  ``updown``: a meridian field's form, poles and up-down asymmetry.
"""
