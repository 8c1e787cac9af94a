import sys

from ohra.cli.synth import run

sys.exit(run())
