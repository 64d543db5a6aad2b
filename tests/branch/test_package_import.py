"""``vesicle_opt.branch`` is the ``branch`` function (the public ``vo.branch(scene, ...)``), and its
submodules still import by every spelling: ``import vesicle_opt.branch.run as r`` walks attributes
from ``vesicle_opt`` (it raised ImportError: "cannot import name 'run' from 'branch'"), so each
submodule is bound on the function too. Fresh interpreters: the order of the first imports matters."""

import subprocess
import sys

import pytest

CASES = {
    # the package's own submodule (loaded by the package), then the front door's name
    "as, first": "import vesicle_opt.branch.run as r; import vesicle_opt as vo; "
                 "print(r.__name__, vo.branch is r.branch)",
    # a submodule the package does not load (branch.reference), after the front door's name
    "as, later": "import vesicle_opt as vo; vo.branch; import vesicle_opt.branch.reference as m; "
                 "from vesicle_opt.branch import reference; print(m.__name__, m is reference)",
    "from": "from vesicle_opt.branch import run; import vesicle_opt as vo; print(run.__name__, vo.branch is run.branch)",
}
EXPECTED = {"as, first": ["vesicle_opt.branch.run", "True"], "as, later": ["vesicle_opt.branch.reference", "True"],
            "from": ["vesicle_opt.branch.run", "True"]}


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_branch_submodule_imports_by_every_spelling(case):
    out = subprocess.run([sys.executable, "-c", CASES[case]], capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout.split() == EXPECTED[case], out.stdout + out.stderr


def test_the_front_door_name_stays_the_function():
    import types

    import vesicle_opt as vo
    import vesicle_opt.branch.run as r

    assert isinstance(vo.branch, types.FunctionType) and vo.branch is r.branch and vo.branch.run is r
