"""``python -m ohra.synth``: the same command as ``ohra synth`` (see :mod:`ohra.cli.synth`)."""

import sys

from ohra.cli.synth import main

sys.exit(main())
