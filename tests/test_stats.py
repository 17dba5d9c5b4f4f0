"""The success-interval computation (Wilson score, 95%)."""

import math

import pytest

from training.plumbing.stats import format_success, success, wilson_interval


@pytest.mark.parametrize(
    ("k", "n", "lo", "hi"),
    [  # reference values: statsmodels 0.15 proportion_confint(k, n, method="wilson")
        (10, 10, 0.7224672, 1.0),
        (0, 10, 0.0, 0.2775328),
        (46, 50, 0.8116175, 0.9684505),
        (195, 200, 0.9428217, 0.9892753),
        (100, 200, 0.4313609, 0.5686391),
    ],
)
def test_wilson_matches_reference_values(k, n, lo, hi):
    a, b = wilson_interval(k, n)
    assert a == pytest.approx(lo, abs=1e-6) and b == pytest.approx(hi, abs=1e-6)


def test_wilson_contains_the_rate_and_narrows_with_n():
    for k, n in [(3, 7), (99, 100), (1, 1000)]:
        lo, hi = wilson_interval(k, n)
        assert lo <= k / n <= hi
        lo2, hi2 = wilson_interval(10 * k, 10 * n)
        assert hi2 - lo2 < hi - lo


def test_wilson_refuses_impossible_counts():
    for k, n in [(1, 0), (-1, 5), (6, 5)]:
        with pytest.raises(ValueError):
            wilson_interval(k, n)


def test_success_counts_complete_steps():
    s = success([25, 19, 20, 0], min_steps=20)
    assert (s["successes"], s["episodes"]) == (2, 4) and math.isclose(s["rate"], 0.5)
    assert format_success(s).startswith("50.0% [")


def test_wilson_is_exact_at_the_ends():
    assert wilson_interval(200, 200)[1] == 1.0 and wilson_interval(0, 200)[0] == 0.0


def test_iqm_is_the_mean_of_the_middle_half_with_a_bootstrap_interval_around_it():
    from training.plumbing.stats import iqm, iqm_interval

    assert iqm([1.0, 2.0, 3.0, 4.0]) == 2.5  # the middle two
    assert iqm([0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0]) == 1.0  # two failures cut
    assert iqm_interval([1.0] * 5) == (1.0, 1.0, 1.0)
    centre, lo, hi = iqm_interval([0.0, 0.2, 0.5, 0.9, 1.0, 1.0, 0.95, 0.3], reps=2000)
    assert lo < centre < hi and 0.0 <= lo and hi <= 1.0
    assert iqm_interval([0.0, 0.2, 0.5, 0.9, 1.0, 1.0, 0.95, 0.3], reps=2000) == (centre, lo, hi)
