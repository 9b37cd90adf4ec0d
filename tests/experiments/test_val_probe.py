"""The validation probe scores fit-scene on validation views, never on test views."""

import numpy as np

from experiments.tasks.scene_task import SceneTask, load_task_scene
from experiments.studies.val_probe import scored_on_validation


def test_the_scored_views_are_the_validation_views():
    task = SceneTask(scene="object", size=16, frames=2, n_test=2, n_val=0)
    probe = scored_on_validation(3)(task)
    full = load_task_scene(SceneTask(scene="object", size=16, frames=2, n_test=2, n_val=3))
    assert len(probe.test) == 3 and probe.val == []
    for a, b in zip(probe.test, full.val, strict=True):
        np.testing.assert_array_equal(a.rgb, b.rgb)
    assert not any(np.array_equal(a.rgb, b.rgb) for a in probe.test for b in full.test)
