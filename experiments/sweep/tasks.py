"""The tasks a sweep can run, and how a cell's settings become a task object.

A task is a frozen dataclass plus a ``run_*(task, progress=False) -> dict`` function in
its own module. A cell's settings are matched to the dataclass's fields *by name*
(``dataclasses.fields``), so a field added to a task flows through the sweep without
code changes here. The only translations are listed in :class:`TaskKind`:

* ``dataset`` (the sweep's generic name) becomes the task's own field
  (``image`` for the image task, ``scene`` for the scene task);
* ``reassign = "auto"`` means on for batch image fits and off for patch streams
  (as ``fit-image --reassign auto`` does);
* ``depth_model = "sensor"`` means ``None``: use the dataset's own depth.

A field that holds a nested config of method constants (the scene task's ``evidence``,
``growth``, ``prior``, ``budget``, ``baseline``) is reached by dotted name,
``evidence.forget_after``, as ``tune`` reaches it (a TOML table ``evidence.forget_after =
[6, 0]`` in a grid is read as that name): :func:`nested_default` gives its default,
:func:`build_task` sets it with :func:`vbgs.mapping.with_dotted`, and the nested config
refuses a value it cannot take.

Modules are imported lazily, so a task whose module is not there yet (the scene task
while it is being written) only fails for the cells that need it.
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path


class TaskUnavailable(ValueError):
    """A task's module cannot be imported."""


def _image_values(values: dict) -> dict:
    if values.get("reassign", "auto") == "auto":
        values["reassign"] = values.get("stream", "none") == "none"
    return values


def _scene_values(values: dict) -> dict:
    if values.get("depth_model") in ("sensor", "none", ""):
        values["depth_model"] = None
    return values


def _image_names() -> tuple[str, ...]:
    from vbgs.data.images import BUNDLED

    return BUNDLED


def _scene_names() -> tuple[str, ...]:
    from vbgs.data.synthetic import SCENES

    return tuple(SCENES)


@dataclass(frozen=True)
class TaskKind:
    """Where a task lives and how the sweep's generic settings map onto it."""

    name: str
    module: str
    cls: str
    run: str
    dataset_field: str  # the task field the sweep's ``dataset`` setting fills
    dataset_names: Callable[[], tuple[str, ...]]  # built-in datasets; others are paths
    translate: Callable[[dict], dict] = field(default=lambda values: values)

    def available(self) -> bool:
        return importlib.util.find_spec(self.module) is not None

    def load(self) -> tuple[type, Callable]:
        """The task dataclass and its run function."""
        try:
            mod = importlib.import_module(self.module)
        except ModuleNotFoundError as err:
            if err.name != self.module:
                raise TaskUnavailable(f"task {self.name!r}: importing {self.module} failed: "
                                      f"{err}") from err
            raise TaskUnavailable(
                f"task {self.name!r} needs the module {self.module}, which is not installed "
                "in this checkout yet; drop the task from the config or update the code"
            ) from err
        except Exception as err:  # a module that is there but broken: say which
            raise TaskUnavailable(f"task {self.name!r}: importing {self.module} failed: "
                                  f"{type(err).__name__}: {err}") from err
        try:
            return getattr(mod, self.cls), getattr(mod, self.run)
        except AttributeError as err:
            raise TaskUnavailable(f"task {self.name!r}: {self.module} has no {err.name} "
                                  f"(expected {self.cls} and {self.run})") from err

    def fields(self) -> dict[str, dataclasses.Field]:
        """The task dataclass's fields by name (the settings a cell can pass through)."""
        cls, _ = self.load()
        return {f.name: f for f in dataclasses.fields(cls)}

    def dataset_exists(self, dataset: str) -> bool:
        return dataset in self.dataset_names() or Path(dataset).expanduser().exists()


TASKS: dict[str, TaskKind] = {
    "image": TaskKind("image", "experiments.tasks.image_task", "ImageTask", "run_image",
                      "image", _image_names, _image_values),
    "scene": TaskKind("scene", "experiments.tasks.scene_task", "SceneTask", "run_scene",
                      "scene", _scene_names, _scene_values),
}

# Settings every cell may carry whatever its task: they describe the cell.
DESCRIPTIVE = ("task", "dataset", "method")


def task_fields(task: str) -> set[str]:
    """Names a cell of ``task`` passes to its dataclass (``dataset`` included)."""
    kind = TASKS[task]
    return (set(kind.fields()) - {kind.dataset_field}) | {"dataset"}


def field_default(f: dataclasses.Field):
    """A dataclass field's default (its factory's product; None when it has neither)."""
    if f.default is not dataclasses.MISSING:
        return f.default
    return f.default_factory() if f.default_factory is not dataclasses.MISSING else None


def nested_default(task: str, name: str):
    """The default of the dotted setting ``name`` (``evidence.forget_after``) of ``task``:
    a leaf of a field that holds a nested config. KeyError when ``name`` is not one."""
    from vbgs.mapping.config import get_dotted  # the task's fields imported JAX already

    head, dot, rest = name.partition(".")
    f = TASKS[task].fields().get(head)
    if not dot or f is None:
        raise KeyError(name)
    try:
        value = get_dotted(field_default(f), rest)
    except ValueError:
        raise KeyError(name) from None
    if dataclasses.is_dataclass(value):  # a config, not one of its constants
        raise KeyError(name)
    return value


def is_nested(task: str, name: str) -> bool:
    """Whether ``name`` is a dotted setting of ``task`` (:func:`nested_default`)."""
    try:
        nested_default(task, name)
    except KeyError:
        return False
    return True


def build_task(settings: dict):
    """The task object for a cell: its dataclass built from the settings it has fields for,
    then its dotted settings set in its nested configs."""
    from vbgs.mapping import with_dotted  # JAX: imported when a cell is built

    kind = TASKS[settings["task"]]
    cls, _ = kind.load()
    values = dict(settings)
    values[kind.dataset_field] = values.pop("dataset")
    values = kind.translate(values)
    names = {f.name for f in dataclasses.fields(cls)}
    task = cls(**{k: v for k, v in values.items() if k in names})
    for name, value in sorted(values.items()):
        if "." in name and is_nested(settings["task"], name):
            task = with_dotted(task, name, value)
    return task


def run_task(settings: dict) -> dict:
    """Build and run one cell's task; returns the task's result as a dict (a typed
    result, such as :class:`experiments.tasks.protocol.SceneResult`, through ``to_dict``)."""
    _, run = TASKS[settings["task"]].load()
    result = run(build_task(settings), progress=False)
    return result.to_dict() if hasattr(result, "to_dict") else result
