"""The stage timer: each stage charged its own time, a stage inside another not twice."""

import time

from vbgs.mapping import stages


def test_an_inner_stage_is_charged_to_itself_not_to_the_outer_one():
    with stages.timing() as seconds:
        with stages.stage("outer"):
            time.sleep(0.02)
            with stages.stage("inner"):
                time.sleep(0.05)
            with stages.stage("inner"):  # a second visit adds to the same name
                time.sleep(0.05)
    assert 0.1 <= seconds["inner"] < 0.2
    assert 0.02 <= seconds["outer"] < 0.07  # its own sleep only, not the inner 0.1 s


def test_a_stage_that_returns_early_is_timed_and_closed():
    def early():
        with stages.stage("early"):
            time.sleep(0.01)
            return 1

    with stages.timing() as seconds:
        with stages.stage("outer"):
            early()
    assert seconds["early"] >= 0.01 and seconds["outer"] < seconds["early"]
    assert stages._open == []


def test_outside_timing_nothing_is_timed():
    with stages.stage("alone") as done:
        assert done(1) == 1
    assert stages._seconds[0] is None and stages._open == []
