"""The optional extras: whether each one *loads*, not only whether it is installed.

``find_spec`` finds a package whose import then fails (pyFFTW with its shared library missing, a
JAX whose jaxlib does not match): each extra is imported once, here, and the outcome kept.

* ``require(module, key, value)``: an explicit choice (``solver.fft = "pyfftw"``, ``solver.array =
  "jax"``) whose extra does not load is an ``InputError`` before any work: the key, the import
  error, and the install command.
* ``usable(module, key)``: an ``"auto"`` choice: False, with one warning line naming the extra and
  the import error (once per process), when the extra is installed but does not load; False
  silently when it is not installed (the always-installed path is the documented default then).

``import_pyfftw`` is pyFFTW's import without the interfaces it builds over dask and scipy.fftpack
(``mesh.fftlib`` uses the ``FFTW`` class only).
"""

from __future__ import annotations

import importlib
import importlib.util
import logging
import sys

from vesicle_opt.errors import InputError

EXTRAS = {"pyfftw": "fftw", "jax": "jax", "qdldl": "ldl"}  # module -> the extra of pyproject.toml that installs it
PYFFTW_UNUSED = ("dask.array.fft", "scipy.fftpack")  # what pyfftw's interfaces wrap, never used here
_outcome: dict[str, str | None] = {}  # module -> None (loads) or the import error, one line
_warned: set[str] = set()
log = logging.getLogger(__name__)


def import_pyfftw():
    """pyfftw (optional extra, third-party: only solver.fft = "pyfftw" needs it), imported without
    the interfaces it builds over dask and scipy.fftpack: its package ``__init__`` imports them
    when they are installed (0.35 s measured, inside the first solve's wall time), and only the
    ``FFTW`` class is used here. A module not yet imported is hidden for that one import by
    ``sys.modules[name] = None`` (an import of it then raises ImportError, which pyfftw catches)
    and restored after; ``import pyfftw.interfaces.dask_fft`` later still works."""
    if "pyfftw" in sys.modules:
        return sys.modules["pyfftw"]
    hidden = [name for name in PYFFTW_UNUSED if name not in sys.modules]
    for name in hidden:
        sys.modules[name] = None
    try:
        import pyfftw
    finally:
        for name in hidden:
            if sys.modules.get(name, 0) is None:
                del sys.modules[name]
    return pyfftw


def installed(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


def load_error(module: str) -> str | None:
    """None when ``module`` imports; else its import error in one line (also "not installed")."""
    if module not in _outcome:
        if not installed(module):
            _outcome[module] = "not installed"
        else:
            try:
                import_pyfftw() if module == "pyfftw" else importlib.import_module(module)
                _outcome[module] = None
            except Exception as exc:  # noqa: BLE001 - a broken extra raises ImportError, OSError, AttributeError...
                text = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
                _outcome[module] = f"{type(exc).__name__}: {text}"[:200]
    return _outcome[module]


def install_hint(module: str) -> str:
    return f"pip install 'vesicle_opt[{EXTRAS[module]}]'"


def require(module: str, key: str, value: str) -> None:
    """InputError (``key``) when the extra of ``module`` does not load (module docstring)."""
    why = load_error(module)
    if why is not None:
        raise InputError(key, f"{value!r} needs the optional extra {EXTRAS[module]!r}, which does not load "
                         f"({why}); install it: {install_hint(module)}")


def usable(module: str, key: str, fallback: str) -> bool:
    """Whether an ``"auto"`` choice may use ``module`` (module docstring); ``fallback`` names the
    always-installed path for the warning."""
    why = load_error(module)
    if why is None:
        return True
    if why != "not installed" and module not in _warned:
        _warned.add(module)
        log.warning(f"{key} = 'auto': the optional extra {EXTRAS[module]!r} is installed but does not load "
                    f"({why}); using {fallback} (reinstall it: {install_hint(module)})")
    return False
