"""Execution backends for per-shard tasks: a local process pool (default) and Ray.

A task is a picklable tuple and its function a module-level callable returning a picklable
result; results come back to the driver as they finish (any order), and only the driver writes
files. Both backends run the same function on the same tuple, so a seeded task gives the same
bytes on either (tested).

Ray (``pip install -e ".[ray]"``): without ``address`` a local cluster with ``workers`` CPUs is
started and stopped around the run; with ``address`` (``auto``, ``ray://host:10001`` or
``host:6379``) the run joins that cluster and uses whatever CPUs it has, one per task. Every node
needs ohra installed and the object files at the same paths (shared storage), or objects that need
no files (built-ins, procedural).
"""

from __future__ import annotations

import importlib.util
import multiprocessing as mp
import signal
from typing import Callable, Iterable, Iterator

from ohra.errors import OhraError

BACKENDS = ("process", "ray")


def check_backend(backend: str, address: str | None = None) -> None:
    """Refuse an unknown backend, ``address`` without Ray, the Ray backend without Ray installed, or an address where
    nothing answers (:func:`probe_address`): before a job creates its output folder or draws its bar, not after."""
    if backend not in BACKENDS:
        raise OhraError(f"unknown backend {backend!r}; expected one of {', '.join(BACKENDS)}")
    if backend != "ray" and address:
        raise OhraError("--address is for the ray backend; add --backend ray")
    if backend == "ray" and importlib.util.find_spec("ray") is None:
        raise OhraError('the ray backend needs Ray: pip install -e ".[ray]"')
    if backend == "ray" and address:
        probe_address(address)  # here, before a progress bar is drawn: its first frame preceded the one-line error


def run_tasks(fn: Callable, tasks: list, backend: str = "process", workers: int = 1,
              address: str | None = None) -> Iterator:
    """Yield ``fn(task)`` for every task, in completion order."""
    check_backend(backend, address)
    if int(workers) < 1:
        raise OhraError(f"workers must be >= 1, got {workers}")
    if not tasks:
        return iter(())
    if backend == "ray":
        return _ray(fn, tasks, int(workers), address)
    return _pool(fn, tasks, int(workers))


def _pool(fn: Callable, tasks: list, workers: int) -> Iterable:
    if workers == 1 or len(tasks) == 1:
        for t in tasks:
            yield fn(t)
        return
    # fork: workers start with the driver's imports and caches (objects' bodies already settled)
    with mp.get_context("fork").Pool(min(workers, len(tasks)), initializer=_ignore_sigint) as pool:
        yield from pool.imap_unordered(fn, tasks)


def _ignore_sigint() -> None:
    """Pool workers leave Ctrl-C to the driver, which stops them: each printed its own KeyboardInterrupt
    traceback ("Process ForkPoolWorker-7: ...") before the driver's one-line ``ohra: interrupted``. SIGTERM and
    SIGHUP get their defaults back (the CLI turns them into Ctrl-C in the driver; a pool stops its workers with
    SIGTERM, which must end them, not raise in them)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for sig in (signal.SIGTERM, getattr(signal, "SIGHUP", None)):
        if sig is not None:
            signal.signal(sig, signal.SIG_DFL)


PROBE_TIMEOUT_S = 5.0


def probe_address(address: str, timeout: float = PROBE_TIMEOUT_S) -> None:
    """Refuse a ``host:port`` / ``ray://host:port`` address where nothing accepts a TCP connection within
    ``timeout`` seconds: Ray itself waits minutes on an unreachable host before failing. ``auto`` and
    addresses this does not parse are left to Ray."""
    import socket

    hostport = address.split("://", 1)[1] if "://" in address else address
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as exc:
        why = "no answer" if isinstance(exc, TimeoutError) else (exc.strerror or type(exc).__name__).lower()
        raise OhraError(f"--address {address}: no Ray cluster reachable ({why} at {host}:{port} within {timeout:g} s); "
                        "check the head node's address and port, or leave --address out for a local cluster") from None


def _ray(fn: Callable, tasks: list, workers: int, address: str | None) -> Iterable:
    try:
        import ray
    except ImportError:
        raise OhraError('the ray backend needs Ray: pip install -e ".[ray]"') from None
    started = not ray.is_initialized()
    if started:
        if address:
            probe_address(address)
            try:
                ray.init(address=address, log_to_driver=False)
            except ConnectionError as exc:  # no cluster there: one line, not Ray's traceback
                raise OhraError(f"--address {address}: no Ray cluster reachable ({str(exc).splitlines()[0][:200]}); start one "
                                "with `ray start --head`, or leave --address out for a local cluster") from None
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
    try:
        remote = ray.remote(num_cpus=1, max_retries=2)(fn)
        pending = [remote.remote(t) for t in tasks]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        if started:
            ray.shutdown()
