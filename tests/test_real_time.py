"""Recorded time played in real time (`sds_ros.real_time.RealTimePace`), on a fake clock."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import pytest
from sds_ros.real_time import BEHIND_REPORT_S, REPORT_PERIOD_S, RealTimePace


class FakeClock:
    """A monotonic clock that moves only when slept on or pushed (`work`)."""

    def __init__(self) -> None:
        self.now_s = 100.0
        self.slept_s: list[float] = []

    def __call__(self) -> float:
        return self.now_s

    def sleep(self, seconds: float) -> None:
        self.slept_s.append(seconds)
        self.now_s += seconds

    def work(self, seconds: float) -> None:
        self.now_s += seconds


def pace_on(clock: FakeClock, rate: float, warn: Callable[[str], object]) -> RealTimePace:
    """A pace on `clock`, started now, that tells `warn`."""
    pace = RealTimePace(rate, warn, "the decoder is slow: frames come late", clock=clock,
                        sleep=clock.sleep)
    pace.start(clock())
    return pace


def test_a_player_that_keeps_up_sleeps_until_each_moment_and_says_nothing() -> None:
    clock, said = FakeClock(), []
    pace = pace_on(clock, rate=2.0, warn=said.append)
    for media_s in (0.1, 0.5, 1.0, 3.0):
        clock.work(0.03)
        pace.wait_until(media_s)
        assert clock() == pytest.approx(100.0 + media_s / 2.0)   # due: it slept to it
    assert said == [] and pace.behind_s == 0.0 and pace.behind_clause() == ""


def test_a_player_behind_plays_at_once_and_says_so_at_most_every_period() -> None:
    """Each moment takes 0.23 s of work for 0.1 s of media time, so moment k is 0.13·k s late:
    from moment 4 (0.52 s, past BEHIND_REPORT_S) on it says so, at the first moment once
    REPORT_PERIOD_S has passed since it last did, and never sleeps."""
    clock, said_at_s = FakeClock(), []
    said: list[str] = []

    def warn(line: str) -> None:
        said.append(line)
        said_at_s.append(clock())

    pace = pace_on(clock, rate=1.0, warn=warn)
    work_s, moments = 0.23, 400
    for index in range(moments):
        pace.wait_until(index * 0.1)
        clock.work(work_s)
    assert said[0] == "playing 0.5 s behind real time (the decoder is slow: frames come late)"
    assert said_at_s[0] == pytest.approx(100.0 + 4 * work_s)
    periods = [later - earlier for earlier, later in itertools.pairwise(said_at_s)]
    assert all(REPORT_PERIOD_S <= period < REPORT_PERIOD_S + work_s for period in periods)
    last_moment_s = clock() - work_s
    assert last_moment_s - said_at_s[-1] < REPORT_PERIOD_S + work_s   # said to the end
    assert pace.behind_s == pytest.approx((moments - 1) * (work_s - 0.1))
    assert pace.behind_clause() == ", up to 51.9 s behind real time"
    assert clock.slept_s == []


def test_lateness_within_the_bound_is_not_kept() -> None:
    clock, said = FakeClock(), []
    pace = pace_on(clock, rate=1.0, warn=said.append)
    clock.work(BEHIND_REPORT_S * 0.9)
    pace.wait_until(0.0)
    assert said == [] and pace.behind_s == 0.0
