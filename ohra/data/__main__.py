import sys

from ohra.cli.data import main

sys.exit(main())
