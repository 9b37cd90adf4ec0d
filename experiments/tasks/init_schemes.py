"""Where a learner starts (``init``), declared once for the CLI, the tasks and the tables:

* ``stream`` (default): from the first batch; components are added as data arrive
  (:mod:`vbgs.inference.grow`); nothing later in the stream is read;
* ``data``: components on points drawn from the **whole** stream, in the bounds of the
  whole scene: an **oracle start** for a stream (it peeks at the future);
* ``random``: uniform in the whole scene's bounds: an oracle start too (the bounds).

A batch fit sees all its data at once, so no start is an oracle there.
"""

INITS = ("stream", "data", "random")
ORACLE_STARTS = ("data", "random")  # read the whole stream before the first batch
INIT_HELP = ("stream (default): start from the first batch, add components as data arrive; "
             "data: on points of the whole stream (an oracle start for a stream); "
             "random: uniform in the whole scene's bounds (an oracle start too)")


def oracle_start(init: str) -> bool:
    """Whether a stream started with ``init`` reads data that has not arrived yet."""
    if init not in INITS:
        raise ValueError(f"unknown init {init!r}: use one of {INITS}")
    return init in ORACLE_STARTS
