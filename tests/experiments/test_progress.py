"""Progress off a terminal: plain log lines with rate and time left, and a line while the
first items compile."""

import io

from experiments.progress import LogLines


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_log_lines_every_few_seconds_with_rate_and_time_left():
    out, clock = io.StringIO(), Clock()
    bar = LogLines(total=60, desc="frames", unit="frame", stream=out, every=5, clock=clock)
    clock.t = 20.0  # the first frame compiles for 20 s
    bar.update()
    for _ in range(10):  # then 2 frames a second
        clock.t += 0.5
        bar.update()
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("frames 0/60: compiling on the first frame")
    assert lines[1] == "frames 1/60"  # at 20 s: no rate yet (the compile is not a rate)
    assert lines[2] == "frames 11/60, 2 frames/s, 24 s left"
    assert lines[3] == "frames 11/60 done in 25 s" and len(lines) == 4


def test_iterating_counts_and_silent_when_disabled():
    out = io.StringIO()
    assert list(LogLines(range(3), desc="x", stream=out, every=1e9)) == [0, 1, 2]
    assert out.getvalue() == "x 0/3: compiling on the first it (or loading the compile cache) ...\n"
    silent = LogLines(range(3), stream=None)
    assert list(silent) == [0, 1, 2] and silent.n == 3 and silent.lines == 0
