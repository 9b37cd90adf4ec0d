"""The scene learner as library functions: ``init``, ``update`` (a frame),
``update_points`` (a batch of points: the one stream loop's step, which every frame goes
through), ``splats`` over a :class:`MapState`, with every hyperparameter in one nested
:class:`Config`; ``mapper`` binds them (see :mod:`vbgs.mapping.mapper`)."""

from vbgs.mapping.config import (
    BudgetConfig,
    Config,
    EvidenceConfig,
    GrowthConfig,
    RenderConfig,
    SensorConfig,
    dotted_names,
    get_dotted,
    with_dotted,
)
from vbgs.mapping.mapper import (
    MapInfo,
    Mapper,
    MapState,
    bound,
    grow_components,
    init,
    mapper,
    settled,
    splats,
    update,
    update_points,
)
from vbgs.mapping.store import load, save

__all__ = ["BudgetConfig", "Config", "EvidenceConfig", "GrowthConfig", "MapInfo", "MapState",
           "Mapper", "RenderConfig", "SensorConfig", "bound", "dotted_names", "get_dotted",
           "grow_components", "init", "load", "mapper", "save", "settled", "splats",
           "update", "update_points", "with_dotted"]
