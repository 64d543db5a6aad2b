"""``python -m vesicle_opt ...`` is the ``vesicle-opt`` command (``vesicle_opt.cli``)."""

import sys

from vesicle_opt.cli import main

sys.exit(main())
