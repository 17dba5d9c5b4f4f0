"""Success rates with 95% intervals: the walking claims' statistics.

A success is an episode of at least :data:`MIN_STEPS` complete strict steps in its 30 s. A
rate over n episodes comes with the Wilson score interval (Wilson 1927), which stays inside
[0, 1] and keeps its coverage near 0 and 1 where the normal approximation fails (10 of 10
successes: [0.72, 1.00], not [1.00, 1.00]).
"""

from __future__ import annotations

import math

MIN_STEPS = 20
"""Complete steps in a 30 s episode that make it a success (walking, not a stumble)."""
Z95 = 1.959963984540054
"""The standard normal's 97.5% quantile (a two-sided 95% interval)."""


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of k successes in n trials (95% by default)."""
    if n <= 0 or not 0 <= k <= n:
        raise ValueError(f"need 0 <= k <= n and n > 0, got k={k}, n={n}")
    p = k / n
    den = 1.0 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    lo = 0.0 if k == 0 else min(max(0.0, mid - half), p)  # exact at the ends: 0 and 1
    hi = 1.0 if k == n else max(min(1.0, mid + half), p)
    return lo, hi


def success(steps: list[int], min_steps: int = MIN_STEPS) -> dict:
    """Successes, episodes, rate and its 95% interval of episodes' completed steps."""
    n = len(steps)
    k = sum(s >= min_steps for s in steps)
    lo, hi = wilson_interval(k, n)
    return {"successes": k, "episodes": n, "rate": k / n, "ci95": (lo, hi), "min_steps": min_steps}


def format_success(s: dict) -> str:
    """``97.5% [94.3, 98.9] (195/200)``."""
    lo, hi = s["ci95"]
    return (
        f"{100 * s['rate']:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}] "
        f"({s['successes']}/{s['episodes']})"
    )


def iqm(x) -> float:
    """The interquartile mean: the mean of the middle 50% (SciPy's 25%-trimmed mean)."""
    from scipy.stats import trim_mean

    return float(trim_mean(x, 0.25))


def iqm_interval(scores, reps: int = 20_000, seed: int = 0) -> tuple[float, float, float]:
    """(IQM, low, high) of per-seed scores with a 95% percentile bootstrap over the seeds.

    The interquartile mean and the bootstrap interval that rliable (Agarwal et al. 2021)
    recommends for claims across training seeds; with one task its stratified bootstrap is
    this one, resampling the runs (SciPy's ``bootstrap``, percentile method).
    """
    import numpy as np
    from scipy.stats import bootstrap

    x = np.asarray(scores, dtype=float)
    if x.size < 2 or np.all(x == x[0]):  # no spread: every resample gives the same IQM
        return iqm(x), float(iqm(x)), float(iqm(x))
    res = bootstrap((x,), iqm, n_resamples=reps, method="percentile",
                    rng=np.random.default_rng(seed), vectorized=False)  # fmt: skip
    return iqm(x), float(res.confidence_interval.low), float(res.confidence_interval.high)
