"""The phase-field model on a discretisation, in one home per concept.

* ``functionals``: E_h (6), A (7), B (8) and their gradients, for numpy and CasADi, and the
  pointwise nonlinearities W, g and their derivatives that every other form uses;
* ``lumped``: the same with Hessian-vector products, matrix-free (lumped mass, nodal quadrature),
  and the constant-coefficient bulk model (Fourier symbol, sparse S) of the preconditioners;
* ``penalty``: the penalised energy E_M (11) (numbers and CasADi expressions), exact residuals,
  the round-off floor, the M schedule;
* ``problem``: (alpha, beta), starts and the scaling of the stopping test;
* ``feasibility``: the phase-field bound beta_min(alpha) checked before any solve.
"""
