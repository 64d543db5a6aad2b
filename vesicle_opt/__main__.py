"""``python -m vesicle_opt ...`` is the ``vesicle-opt`` command (``vesicle_opt.cli``)."""

from vesicle_opt.cli import run

run()
