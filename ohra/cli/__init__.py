"""The ``ohra`` command line: a thin layer over the library API, one module per command group."""

from ohra.cli.main import main

__all__ = ["main"]
