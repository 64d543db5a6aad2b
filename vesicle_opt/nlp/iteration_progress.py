"""IPOPT's iterations as a progress bar (``io.progress.bar``), through CasADi's ``iteration_callback``.

Attached by ``nlp.ipopt.make_solver`` only while progress is on (the CLI; never for library use or
the tests), so a solve's numbers cannot depend on it: the callback reads the iterate IPOPT hands
it (objective, constraint values) and returns 0 ("go on"). One bar per IPOPT call (a
continuation's stages each get their own); ``run_ipopt`` closes it when the call returns.
"""

from __future__ import annotations

import numpy as np

from vesicle_opt.io import progress


def IterationProgress(nx: int, ng: int, n_p: int, label: str = "IPOPT"):
    """The callback object (``_callback_class``'s instance). casadi is imported only here, when a
    bar is attached, so importing this module (and ``nlp.ipopt``) does not load it."""
    return _callback_class()(nx, ng, n_p, label)


def _callback_class():
    import casadi as ca  # third-party, lazy: only an IPOPT solve with progress on needs it

    class _IterationProgress(ca.Callback):
        """``iteration_callback`` of ``ca.nlpsol``: one ``update`` per IPOPT iteration."""

        def __init__(self, nx: int, ng: int, n_p: int, label: str = "IPOPT"):
            ca.Callback.__init__(self)
            self.nx, self.ng, self.n_p, self.label = nx, ng, n_p, label
            self.bar = None
            self.construct("iteration_progress", {})

        def get_n_in(self):
            return ca.nlpsol_n_out()

        def get_n_out(self):
            return 1

        def get_name_in(self, i):
            return ca.nlpsol_out(i)

        def get_name_out(self, i):
            return "ret"

        def get_sparsity_in(self, i):
            size = {"f": 1, "x": self.nx, "lam_x": self.nx, "g": self.ng, "lam_g": self.ng, "lam_p": self.n_p}
            return ca.Sparsity.dense(size.get(ca.nlpsol_out(i), 0), 1)

        def eval(self, arg):
            first = self.bar is None
            if first:  # iteration 0: the start point (IPOPT's iteration count starts after it)
                self.bar = progress.bar(self.label, unit="iterations")
            g = np.asarray(arg[ca.nlpsol_out().index("g")]).ravel()
            viol = float(np.max(np.abs(g))) if g.size else 0.0
            self.bar.set_postfix_str(f"f_scaled = {float(arg[ca.nlpsol_out().index('f')]):.10g}, |g|max = {viol:.1e}",  # E = f nlp.f_scale
                                     refresh=False)
            self.bar.update(0 if first else 1)
            return [0]

        def close(self) -> None:
            if self.bar is not None:
                self.bar.close()
            self.bar = None

    return _IterationProgress
