"""Sharp-interface references, independent of the phase-field path (numpy and scipy only; nothing
of the package is imported): the 2D closed elastica (``elastica``) and the 3D axisymmetric prolate
and oblate vesicles of the spontaneous-curvature model at c0 = 0 (``axisymmetric``), each a spectral
tangent-angle discretisation with exact constraints. The eps -> 0 limit of the phase-field
``reduced_energy`` is their ``reduced_energy`` (study ``sharp_limit``)."""
