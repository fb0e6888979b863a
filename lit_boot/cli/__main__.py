"""``python -m lit_boot.cli ...``: the ``lit-boot`` command."""

import sys

from . import main

sys.exit(main())
