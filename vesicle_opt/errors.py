"""Named exceptions of vesicle_opt, in one module (optimistix style).

Every user-facing failure is one of these; the CLI prints ``str(exc)`` as a single line and
exits with the class's ``exit_code``.
"""

from __future__ import annotations


class VesicleError(Exception):
    """Base class of all vesicle_opt errors."""

    exit_code = 1


class InputError(VesicleError, ValueError):
    """Bad user input: a scene key that is unknown, missing, of the wrong type or out of range."""

    exit_code = 2

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(f"{key}: {message}")


class InfeasibleError(InputError):
    """The constraint data (alpha, beta) admit no phase field (see ``vesicle_opt.model.feasibility``)."""


class SolverError(VesicleError, RuntimeError):
    """A solver did not converge. Raised only with ``throw=True``; carries the partial result."""

    exit_code = 1

    def __init__(self, message: str, result=None):
        self.result = result
        super().__init__(message)


class NotSupported(InputError):
    """A combination the package does not support (a backend, method, mesh or scheme): names the
    key and what is supported. Raised before any work; the CLI exits 2 with one line."""
