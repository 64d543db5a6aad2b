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
        # one line whatever the user's value or a damaged file held (a name with a newline, a CSV field)
        super().__init__(f"{key}: {message}".replace("\r", "\\r").replace("\n", "\\n"))


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


class OutputError(VesicleError):
    """The output directory failed during the run (no space left, a read-only remount, ...): the
    message names the path and where the computed result was written instead. Exit 1: the run
    computed its result, only its place changed."""

    exit_code = 1


class StateFileError(InputError):
    """A state file in ``--out`` (branch.csv, branch.json, a study's CSV, a flow's checkpoint) that
    does not parse or belongs to another run: names the file and what to do; the file is left as
    it is. Exit 2, before any work."""

    def __init__(self, path, message: str, key: str = "--out"):
        self.path = str(path)
        super().__init__(key, f"{self.path}: {message}")
