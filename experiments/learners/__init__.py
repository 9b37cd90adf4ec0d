"""Scene learners by method name; each follows :class:`experiments.tasks.protocol.Learner`.

A learner class takes ``(task, scene)``, has ``PROTOCOLS`` (the protocols it runs),
``check(task)`` (fails on bad settings before any work) and ``details(result)``
(its own numbers for the run's record).
"""

from experiments.learners.gradient_learner import GradientLearner
from experiments.learners.polish_learner import PolishLearner
from experiments.learners.vbgs_learner import VbgsLearner

LEARNERS = {"vbgs": VbgsLearner, "gradient": GradientLearner, "vbgs-polish": PolishLearner}
METHODS = tuple(LEARNERS)

__all__ = ["LEARNERS", "METHODS", "GradientLearner", "PolishLearner", "VbgsLearner"]
