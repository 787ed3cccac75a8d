"""``python -m hil.cli``: the same as the ``eha-hil`` console script."""

import sys

from hil.cli import main

sys.exit(main())
