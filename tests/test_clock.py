"""Clocks: a simulation clock refuses implausible times (issue #12: one /clock froze Utu)."""

from __future__ import annotations

import math

import pytest

from anunnaki.clock import SimClock


def test_a_sim_clock_refuses_a_time_far_ahead_and_goes_on() -> None:
    clock = SimClock(max_jump=60.0)
    assert clock.update(25.0)  # the first time sets the run's time, whatever it is
    assert clock.update(26.0) and clock.now() == 26.0
    assert not clock.update(1e12)  # forged: would freeze every later time at 1e12
    assert not clock.update(math.nan) and not clock.update(math.inf)
    assert clock.now() == 26.0 and clock.refused == 3
    assert clock.update(45.8) and clock.now() == 45.8  # the run's own times still arrive
    assert clock.update(20.0) and clock.now() == 45.8  # backwards: ignored, not refused
    assert clock.refused == 3


def test_without_a_bound_any_finite_time_is_taken() -> None:
    clock = SimClock()
    clock.update(1.0)
    assert clock.update(1e12) and clock.now() == 1e12
    with pytest.raises(ValueError, match="max_jump"):
        SimClock(max_jump=0)
