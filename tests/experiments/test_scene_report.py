"""experiments.tasks.scene_report: what a scene run says on stderr."""

from experiments.tasks.scene_report import warn_all, warn_forgotten
from experiments.tasks.scene_task import SceneTask
from vbgs.mapping import GrowthConfig


def test_forgotten_components_are_said_with_the_count_and_the_way_back(capsys):
    warn_forgotten({"components_forgotten": 7}, SceneTask())
    err = capsys.readouterr().err
    assert "7 components were forgotten" in err
    assert f"{SceneTask().evidence.forget_after} frames in a row" in err
    assert "--forget-after 0" in err
    warn_forgotten({"components_forgotten": 0}, SceneTask())  # nothing forgotten: silent
    warn_forgotten({}, SceneTask())  # a learner without a map: silent
    assert capsys.readouterr().err == ""


def test_colour_is_said_where_it_counts(capsys):
    """By default colour counts with exact depth, behind the colour gate, and the note
    says so; not under a measured sensor, nor with colour off."""
    from vbgs.mapping import with_dotted

    exact = _forgotten(capsys, SceneTask())
    assert "once their depth had shown that the world changes, showed them in another " \
           "colour" in exact
    assert "rims" not in exact  # a static world never opens the gate
    assert "another colour" not in _forgotten(capsys, SceneTask(sensor="kinect"))
    off = with_dotted(SceneTask(), "evidence.recolour_sigmas", 0.0)
    assert "another colour" not in _forgotten(capsys, off)


def _forgotten(capsys, task) -> str:
    warn_forgotten({"components_forgotten": 3}, task)
    return capsys.readouterr().err


def test_forgetting_by_colour_is_said_when_colour_counts(capsys):
    from vbgs.mapping import with_dotted

    ungated = with_dotted(with_dotted(SceneTask(), "evidence.recolour_sigmas", 4.0),
                          "evidence.recolour_gate", 0.0)
    err = _forgotten(capsys, ungated)
    assert "saw through them or showed them in another colour" in err
    assert "rims between differently coloured faces" in err


def test_all_warnings_of_a_clean_run_are_silent_and_of_a_poor_one_speak(capsys):
    warn_all({"points_unlearned": 0.0, "components_forgotten": 0}, SceneTask(), 0.0)
    assert capsys.readouterr().err == ""
    warn_all({"points_unlearned": 0.2, "components_forgotten": 3}, SceneTask(), 0.5)
    err = capsys.readouterr().err
    assert "were not learned" in err and "3 components were forgotten" in err
    assert "drawn as background" in err


def test_a_spent_budget_is_said_with_what_it_cost_the_first_views(capsys):
    from experiments.tasks.scene_report import warn_budget_spent

    details = {"merge_rounds": 4, "components_merged": 1600}
    warn_budget_spent(details, SceneTask(components=20000), (26.10, 25.60))
    err = capsys.readouterr().err
    assert "all 20000 components were in use, so 4 rounds merged 1600 neighbours" in err
    assert "26.10 dB when seen and 25.60 dB at the end (lost 0.50 dB" in err
    assert "--spent-levels 1 grows all the ground met once they are all in use" in err
    coarse = SceneTask(components=20000, growth=GrowthConfig(spent_levels=1))
    warn_budget_spent(details, coarse, (26.10, 25.60))  # already coarser: not offered again
    assert "lost 0.50 dB" in (err := capsys.readouterr().err) and "--spent-levels" not in err
    warn_budget_spent(details, SceneTask(components=20000), (22.71, 23.61))
    err = capsys.readouterr().err
    assert "(gained 0.90 dB meanwhile" in err and "--spent-levels" not in err
    warn_budget_spent({"merge_rounds": 0}, SceneTask(), (1.0, 2.0))  # room to spare: silent
    warn_budget_spent(details, SceneTask(components="auto"), (1.0, 2.0))  # auto: its own
    assert capsys.readouterr().err == ""
    warn_budget_spent(details, SceneTask(), None)  # no early views: the merges alone
    err = capsys.readouterr().err
    assert "rounds merged" in err and "when seen" not in err
