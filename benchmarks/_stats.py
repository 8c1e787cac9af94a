"""Uncertainty of the studies' success rates, from the per-grasp verdicts their evaluations cache.

The grasps of one object are not independent draws of a hand's success (an object is easy or hard for
every grasp), so the intervals here resample objects first (a cluster bootstrap) and then grasps within
each drawn object. Two models evaluated on the same objects draw the *same* objects in a replicate: the
difference between objects is shared, the grasp-level noise is not.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np


def _counts(success: Mapping[str, Sequence[int]], keys: list[str]) -> tuple[np.ndarray, np.ndarray]:
    n = np.array([len(success[k]) for k in keys], dtype=np.int64)
    k = np.array([int(np.sum(success[k])) for k in keys], dtype=np.int64)
    return k, n


def ratio_interval(num: Mapping[str, Sequence[int]], den: Mapping[str, Sequence[int]], level: float = 0.95,
                   reps: int = 4000, seed: int = 0) -> tuple[float, float]:
    """Percentile interval of ``rate(num) / rate(den)``, two evaluations keyed alike (``"hand/object"`` ->
    0/1 verdicts per grasp; the keys must match). Objects are resampled with replacement, shared by both
    evaluations, then each drawn object's grasps are resampled (binomially, independently per evaluation).
    Seeded: the same verdicts give the same interval."""
    if set(num) != set(den):
        raise ValueError(f"the two evaluations cover different pairs: {sorted(set(num) ^ set(den))}")
    keys = sorted(num)
    if not keys:
        raise ValueError("no evaluated pairs")
    rng = np.random.default_rng(seed)
    objs = rng.integers(len(keys), size=(reps, len(keys)))
    rates = []
    for success in (num, den):
        k, n = _counts(success, keys)
        hits = rng.binomial(n[objs], np.where(n > 0, k / np.maximum(n, 1), 0.0)[objs]).sum(axis=1)
        rates.append(hits / n[objs].sum(axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = rates[0] / rates[1]
    ratio = ratio[np.isfinite(ratio)]  # replicates whose denominator drew no success
    if len(ratio) == 0:
        return float("nan"), float("nan")
    lo, hi = np.quantile(ratio, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def pool(*evaluations: Mapping[str, Sequence[int]]) -> dict[str, list[int]]:
    """The verdicts of several evaluations of the same pairs (e.g. models trained with different seeds) as
    one: per ``"hand/object"`` key, their grasps concatenated. :func:`ratio_interval` of pooled evaluations
    then resamples objects shared by all of them and grasps within each; the spread between the pooled
    models themselves is not a level of that bootstrap (report each one's rate beside the pooled one)."""
    if not evaluations:
        raise ValueError("nothing to pool")
    keys = set(evaluations[0])
    for i, e in enumerate(evaluations[1:], 1):
        if set(e) != keys:
            raise ValueError(f"evaluation {i} covers different pairs than evaluation 0: {sorted(set(e) ^ keys)}")
    return {k: [int(v) for e in evaluations for v in e[k]] for k in sorted(keys)}


__all__ = ["pool", "ratio_interval"]
