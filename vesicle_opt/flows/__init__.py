"""Gradient flows of Section 4: schemes (17), (18), (23) with their discrete energy laws.

One module per equation (``penalty`` (18), ``lagrange`` (17), ``backward_euler`` (23) by IPOPT and
``backward_euler_nk`` (23) by the Newton-Krylov minimiser), the exact
discrete f, g in ``discrete``, a physics-free Newton in ``newton`` and a physics-free, I/O-free time
loop in ``stepper``, initial data on the constraint set in ``projection``; output, progress,
checkpoints and stop criteria are ``trackers`` handed to the loop (py-pde style). ``api.flow`` (exported
as ``vesicle_opt.flow``) runs a scene's flow in memory; ``run.write_flow`` (the CLI verb) is that plus
the directory trackers; ``equilibrium.EquilibriumTracker`` ends a flow at a certified equilibrium.
Supported discretisations: FD periodic grids, P1 with lumped mass and nodal quadrature (there the
laws hold to round-off; the consistent mass would need M^{-1} inside f and g), and Fourier-spectral
grids, where (17) and (18) run matrix-free (Jacobian products and GMRES, ``newton.KrylovBordered``)
and (23) as Newton-CG minimising movements.
"""
