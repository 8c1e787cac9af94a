"""The studies' ratio intervals (benchmarks/_stats.py): a cluster bootstrap over objects, shared by the
two evaluations compared, then over grasps."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
try:
    from _stats import pool, ratio_interval
finally:
    sys.path.pop(0)


def _verdicts(rates: dict[str, float], n: int = 100, seed: int = 0) -> dict[str, list[int]]:
    """Exactly round(rate * n) successes per object, in a seeded order."""
    rng = np.random.default_rng(seed)
    return {k: rng.permutation([1] * round(r * n) + [0] * (n - round(r * n))).tolist() for k, r in rates.items()}


# objects that differ a lot in difficulty, as the evaluation objects do
RATES = {f"h/o{i}": r for i, r in enumerate((0.05, 0.15, 0.3, 0.45, 0.6, 0.75, 0.9, 0.2, 0.5, 0.35, 0.65, 0.1, 0.8))}


def test_equal_evaluations_give_a_narrow_interval_around_one():
    """The objects' spread in difficulty cancels because both evaluations draw the same objects: left is
    only the grasp-level noise (~0.1 either side for 1,300 grasps per side at ~45 %)."""
    a = _verdicts(RATES)
    lo, hi = ratio_interval(a, _verdicts(RATES, seed=1))
    assert lo < 1.0 < hi
    assert 0.05 < 1.0 - lo < 0.15 and 0.05 < hi - 1.0 < 0.15


def test_the_objects_are_shared_between_the_two_evaluations():
    """Independent object draws for the two sides (the planted bug) would widen the interval past 0.5."""
    a = _verdicts(RATES)
    lo, hi = ratio_interval(a, a)
    assert hi - lo < 0.3


def test_a_model_at_half_the_rate_is_told_apart():
    half = _verdicts({k: r / 2 for k, r in RATES.items()})
    lo, hi = ratio_interval(half, _verdicts(RATES))
    assert 0.38 < lo < 0.5 < hi < 0.62


def test_a_worse_object_for_one_model_widens_the_interval():
    """When the ratio differs between objects, which objects are drawn matters."""
    worse = dict(RATES, **{"h/o6": 0.3})  # the easiest object, much harder for the first model
    lo, hi = ratio_interval(_verdicts(worse), _verdicts(RATES))
    lo0, hi0 = ratio_interval(_verdicts(RATES, seed=2), _verdicts(RATES))
    assert hi - lo > (hi0 - lo0) * 1.2


def test_seeded_and_checked():
    a, b = _verdicts(RATES), _verdicts(RATES, seed=1)
    assert ratio_interval(a, b, seed=3) == ratio_interval(a, b, seed=3)
    with pytest.raises(ValueError, match="different pairs"):
        ratio_interval(a, {k: v for k, v in b.items() if k != "h/o0"})


def test_pooling_concatenates_each_objects_grasps_across_evaluations():
    """Two seeds' verdicts pool per object: the pooled rate is total successes over total grasps (not the
    mean of per-object rates), and pairs missing from one seed are refused, not dropped."""
    a = {"h/o1": [1, 1, 0, 0], "h/o2": [1, 0]}
    b = {"h/o1": [0, 0, 0, 0], "h/o2": [1, 1]}
    p = pool(a, b)
    assert p == {"h/o1": [1, 1, 0, 0, 0, 0, 0, 0], "h/o2": [1, 0, 1, 1]}
    assert sum(map(sum, p.values())) / sum(map(len, p.values())) == 5 / 12
    with pytest.raises(ValueError, match="o2"):
        pool(a, {"h/o1": [1]})


def test_pooling_two_seeds_narrows_the_ratio_interval():
    """Twice the grasps per object: the grasp-level part of the interval shrinks by about sqrt(2)."""
    one = ratio_interval(_verdicts(RATES, seed=2), _verdicts(RATES, seed=3))
    two = ratio_interval(pool(_verdicts(RATES, seed=2), _verdicts(RATES, seed=4)),
                         pool(_verdicts(RATES, seed=3), _verdicts(RATES, seed=5)))
    assert 0.6 < (two[1] - two[0]) / (one[1] - one[0]) < 0.8
