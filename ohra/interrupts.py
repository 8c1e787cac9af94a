"""Ctrl-C and SIGTERM deferred to a training loop's next safe point, so an interruption keeps the work done.

A trainer checkpoints every N steps; stopped by the default handlers, it loses everything since the last
checkpoint, and a signal that lands inside an optimiser step could leave the weights half-updated. Inside
:class:`DeferredStop` the first SIGINT or SIGTERM only sets :attr:`DeferredStop.requested`; the loop
finishes its step (or epoch, or PPO update), writes a checkpoint, and calls :meth:`DeferredStop.stop`,
which then acts as the signal would have (``KeyboardInterrupt`` for SIGINT, the previous handler for
SIGTERM). A second signal acts at once.

Outside the main thread signals cannot be caught; there the block changes nothing.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from types import FrameType, TracebackType

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class DeferredStop:
    """Context manager: defer SIGINT / SIGTERM to the caller's next :meth:`stop` (a second signal acts at once).

    Usage::

        with DeferredStop("train grasp") as stop:
            for step in ...:
                one_whole_step()
                if stop.requested:
                    save_checkpoint()
                    stop.stop()   # raises KeyboardInterrupt (SIGINT) or ends as SIGTERM would
    """

    def __init__(self, what: str = "training", at: str = "after the current step", quiet: bool = False) -> None:
        self.what, self.at = what, at
        self.quiet = quiet
        self.signum: int | None = None
        self._old: dict[int, object] = {}

    @property
    def requested(self) -> bool:
        """Whether a signal asked the loop to stop."""
        return self.signum is not None

    def __enter__(self) -> "DeferredStop":
        if threading.current_thread() is threading.main_thread():
            for sig in SIGNALS:
                handler = signal.getsignal(sig)
                if handler is signal.SIG_IGN or handler is None:  # ignored (nohup, a worker): leave it so
                    continue
                self._old[sig] = handler
                signal.signal(sig, self._handle)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self._restore()

    def _restore(self) -> None:
        for sig, handler in self._old.items():
            signal.signal(sig, handler)  # type: ignore[arg-type]
        self._old = {}

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is not None:  # the second signal: do not wait for the step
            self._deliver(signum, frame)
            return
        self.signum = signum
        if not self.quiet:
            try:
                print(f"\nohra: stopping {self.what} {self.at} to save a checkpoint (signal again to stop at once)",
                      file=sys.stderr, flush=True)
            except OSError:
                pass

    def stop(self) -> None:
        """Act on the deferred signal now (call after saving): ``KeyboardInterrupt`` for SIGINT, SIGTERM's
        previous handler (by default the process ends by the signal). Returns when none came, or when the previous
        handler returned (it chose to go on): the loop then goes on, and the next signal is deferred again."""
        if self.signum is not None:
            self._deliver(self.signum, None)

    def _deliver(self, signum: int, frame: FrameType | None) -> None:
        old = self._old.get(signum, signal.SIG_DFL)
        self._restore()
        if callable(old):
            old(signum, frame)
        elif signum == signal.SIGINT:
            raise KeyboardInterrupt
        else:
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
        # the handler returned: it chose to go on (a scheduler's "bypass" handler, an outer DeferredStop). So does the
        # loop, with the signals deferred again, until the next one
        self.signum = None
        self.__enter__()
