"""The false-alarm rate bound against a reference written apart (tests/naive.py)."""

import math

import naive
import pytest

from monitor.evaluation.rates import poisson_rate_upper


def test_zero_events_is_rule_of_three():
    # P(0 events) = exp(-mu) = 0.05 gives mu = ln 20 = 2.996 over the hours observed.
    assert poisson_rate_upper(0, 100.0) == pytest.approx(math.log(20.0) / 100.0, rel=1e-9)


@pytest.mark.parametrize("events", [0, 1, 2, 5, 17])
@pytest.mark.parametrize("hours", [0.5, 100.0])
def test_matches_bisection_on_poisson_cdf(events, hours):
    assert poisson_rate_upper(events, hours) == pytest.approx(
        naive.poisson_rate_upper(events, hours), rel=1e-6
    )


def test_more_events_or_fewer_hours_raise_the_bound():
    assert poisson_rate_upper(1, 10.0) > poisson_rate_upper(0, 10.0)
    assert poisson_rate_upper(1, 5.0) > poisson_rate_upper(1, 10.0)
    # With one event in 10 h the bound (0.47/h) exceeds the observed rate (0.1/h).
    assert poisson_rate_upper(1, 10.0) == pytest.approx(0.4744, abs=1e-3)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="hours"):
        poisson_rate_upper(0, 0.0)
    with pytest.raises(ValueError, match="events"):
        poisson_rate_upper(-1, 1.0)
