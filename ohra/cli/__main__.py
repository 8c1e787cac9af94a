import sys

from ohra.cli.main import main

sys.exit(main())
