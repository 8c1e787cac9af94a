"""``python -m ohra.cli``: the ``ohra`` command."""

import sys

from ohra.cli.main import main

sys.exit(main())
