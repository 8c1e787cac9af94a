"""Shared fixtures: published parameter files, and where the shared assets are."""

from __future__ import annotations

import os
from pathlib import Path

# Under pytest-xdist (the README's test command runs one worker per core) each worker and each
# notebook kernel it starts keeps to one BLAS/OpenMP/torch thread: two workers each spinning a
# thread per core made torch tests 5-20x slower than alone. Set before numpy or torch is imported.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[_var] = "1"

import numpy as np
import pytest

from ohra.canonical.params import BaseParams, ExtendedParams, load_params
from ohra.paths import HANDS_ENV, OBJECTS_ENV, hands_root, objects_root

DATA = Path(__file__).parent / "data"


@pytest.fixture
def shadow_base() -> BaseParams:
    return load_params(DATA / "shadow_hand_right_base.json")


@pytest.fixture
def allegro_ext() -> ExtendedParams:
    return load_params(DATA / "allegro_hand_right_extended.json")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


# Tests that need ../shared skip without it when run locally, and say so at the end of the run; CI
# (.ci/run) sets OHRA_REQUIRE_ASSETS=1, which turns the skip into a failure.
REQUIRE_ASSETS_ENV = "OHRA_REQUIRE_ASSETS"
ASSETS_MISSING = "shared assets missing"
BROWSER_MISSING = "no headless Chromium"


@pytest.fixture
def terminal_sigint():
    """Python's own Ctrl-C handler, as in a terminal, for the duration of a test: a pytest started in the
    background of a non-interactive shell inherits SIGINT ignored, where ohra rightly installs nothing."""
    import signal

    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, inherited)


def _require(root: Path) -> Path:
    if not root.is_dir():
        msg = f"{ASSETS_MISSING}: {root} is not a folder"
        if os.environ.get(REQUIRE_ASSETS_ENV) == "1":
            pytest.fail(f"{msg} ({REQUIRE_ASSETS_ENV}=1)")
        pytest.skip(msg)
    return root


@pytest.fixture
def hands_dir() -> Path:
    return _require(hands_root())


@pytest.fixture
def objects_dir() -> Path:
    return _require(objects_root())


# The longest files first (seconds each on the 2-core machine, stop 50: the default suite, then the e2e one). With
# --dist loadfile pytest-xdist hands out files in the order of its work queue, and a long file handed out last keeps one
# worker busy after the other is idle. xdist >= 3.7 orders that queue by each file's number of tests unless told
# not to (pytest_configure below), which had made this list moot: the notebooks, one test each, went last.
LONGEST_FIRST = ("test_notebook_grasp.py", "test_zeroshot_study.py", "test_notebook_rotation.py", "test_data_ray.py",
                 "test_notebook_morphology.py", "test_synth.py", "test_mirror.py", "test_learn_vae.py", "test_data_trust.py",
                 "test_cli.py", "test_data_recipe.py", "test_grasp_eval_resume.py", "test_sim.py", "test_notebook_eval.py",
                 "test_grasp_train.py", "test_viz.py", "test_rl.py", "test_eval_resume.py", "test_learn_geometry.py",
                 "test_grasp_refine.py", "test_synth_capsule_pairs.py", "test_notebook_parse.py", "test_notebook_synthesis.py")


def pytest_configure(config) -> None:
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False  # keep the collection order below (xdist's --no-loadscope-reorder)


def pytest_collection_modifyitems(config, items) -> None:
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: each file keeps its own order


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    """A loud note when tests skipped for missing shared assets or a missing browser."""
    reasons = [str(r.longrepr[2]) if isinstance(r.longrepr, tuple) else str(r.longrepr)
               for r in terminalreporter.stats.get("skipped", [])]
    assets = sum(ASSETS_MISSING in r for r in reasons)
    browser = sum(BROWSER_MISSING in r for r in reasons)
    if assets:
        terminalreporter.write_sep("!", f"{assets} TESTS SKIPPED: SHARED ASSETS MISSING", red=True, bold=True)
        terminalreporter.write_line(f"hands: {hands_root()}  objects: {objects_root()}")
        terminalreporter.write_line(f"Put the assets at ../shared/hands and ../shared/objects beside the repository, or set "
                                    f"{HANDS_ENV} and {OBJECTS_ENV}; CI sets {REQUIRE_ASSETS_ENV}=1 to fail instead of skipping.")
    if browser:
        terminalreporter.write_sep("!", f"{browser} BROWSER TESTS SKIPPED: NO HEADLESS CHROMIUM", red=True, bold=True)
        terminalreporter.write_line("Install it (Debian: apt-get install -y chromium) or set OHRA_CHROMIUM to its path.")
