"""The log axis's ticks: one rule for the report's figures and the live page's box plot."""

import math

from slamrun.core.ticks import log_steps, log_ticks


def test_ticks_are_whole_values_from_the_tick_below_the_least_to_the_one_above_the_greatest():
    assert log_ticks([0.030, 0.043]) == [0.02, 0.05]  # closer together than two ticks: one at each end
    assert log_ticks([0.003, 0.5]) == [0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5]
    assert log_ticks([0.01, 0.01]) == [0.01, 0.02]  # one value on a tick: still an axis
    assert log_ticks([0.0, -1.0, math.nan, math.inf]) == [] and log_ticks([]) == []


def test_over_three_decades_each_decade_is_labelled_once():
    assert log_steps(0.001, 1.0) == (1.0, 2.0, 5.0) and log_steps(1e-5, 3.0) == (1.0,)
    assert log_ticks([1e-5, 3.0]) == [1e-05, 0.0001, 0.001, 0.01, 0.1, 1.0, 10.0]
