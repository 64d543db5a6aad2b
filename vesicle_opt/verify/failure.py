"""What a result that is not certified says where it is reported (a branch row, a study row, the CLI).

``tol_to_certify``: for the outcome ``roundoff_floor`` the least tolerance the certificate can
accept (``verify.certify.certifiable_tol`` of the result's ``kkt_floor``), the column
``certifiable_tol`` of branch and study CSVs; None for every other outcome.
"""

from __future__ import annotations

import math

from vesicle_opt.result import Result, Status
from vesicle_opt.verify.certify import certifiable_tol


def tol_to_certify(result: Result) -> float | None:
    """The tol that can be certified, for a round-off floor (module docstring); else None."""
    floor = result.extra.get("kkt_floor")
    if result.outcome is not Status.ROUNDOFF_FLOOR or floor is None or not math.isfinite(floor):
        return None
    return certifiable_tol(float(floor))
