"""``python -m vesicle_opt.cli ...``: the ``vesicle-opt`` command (``vesicle_opt.cli.run``)."""

from vesicle_opt.cli import run

run()
