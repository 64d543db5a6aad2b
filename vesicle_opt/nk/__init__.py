"""The matrix-free path (large 3D, spectral grids): Newton-Krylov on products, no assembled Hessian.

* ``setup``: operators, preconditioner and symmetry modes of a discretisation; nested-iteration grids;
* ``precond``: the constant-coefficient (Fourier or sparse) model of the Hessian;
* ``krylov``: projected preconditioned CG; ``newton_cg``: inexact Newton-CG with a line search;
* ``options``: the frozen ``NewtonKrylovOptions``; ``solve``: the methods exact, penalty,
  continuation and augmented, certified like the IPOPT path.
"""
