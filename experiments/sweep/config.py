"""Sweep configs: a TOML file -> frozen dataclasses, checked before any cell runs.

Schema (see ``experiments/configs/README.md``)::

    name = "quick"                 # required: names the results folder
    description = "..."            # optional
    [fixed]                        # optional: settings shared by every cell
    size = 64
    [[grid]]                       # one or more; cells = union of their cartesian products
    task = ["image"]               # each value a list, or a scalar meaning [scalar]
    dataset = ["astronaut", "coffee"]
    components = [500, 2000]

A grid's value for a key overrides ``[fixed]``'s. Every key must be a setting in
:data:`SETTINGS` or a field of a task dataclass (so new task fields are accepted
without code changes; their values are type-checked against the field's default).
Errors are :class:`ConfigError` naming the file and the key, e.g.
``quick.toml: grid[0].components: must be an integer >= 1, got -5``.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Callable
from dataclasses import MISSING, dataclass, is_dataclass
from pathlib import Path
from typing import Any

from experiments.tasks.settings import (
    ASSIGN,
    COLOUR_RULE,
    DEPTH_KIND,
    ESTEP,
    FORMAT,
    INIT,
    MEASURED_BY,
    METHOD,
    OPACITY_RULE,
    ORDER,
    POSES,
    PROTOCOL,
    SENSOR,
    SENSOR_HOLES_HELP,
    STREAM,
    valid_splat_scale,
)
from experiments.sweep.tasks import TASKS, TaskUnavailable, field_default, nested_default


class ConfigError(ValueError):
    """A config that cannot run; the message names the file and the key."""


def _replay(value: str) -> str | None:
    """The problem :func:`vbgs.baseline.replay.parse_replay` finds in a spec, or None."""
    # imported here: vbgs.baseline imports JAX, and a local sweep worker imports this
    # module before it sets its thread limits (which must come before JAX)
    from vbgs.baseline.replay import parse_replay

    try:
        parse_replay(value)
    except (TypeError, ValueError) as err:
        return str(err)
    return None


def _depth_model(value: str) -> str | None:
    if value == "sensor":
        return None
    path = Path(value).expanduser()
    if path.suffix != ".onnx":
        return "must be \"sensor\" or the path of an .onnx depth model"
    if not path.is_file():
        return f"depth model file {value!r} does not exist"
    return None


def _sensor_holes(value: str) -> str | None:
    """The problem :func:`vbgs.sensors.parse_holes` finds in a spec, or None."""
    from vbgs.sensors import parse_holes  # NumPy only

    try:
        parse_holes(value)
    except ValueError as err:
        return str(err)
    return None


def _components(value) -> str | None:
    """A count is checked by the minimum; text must be ``auto`` or ``auto:MAX``
    (:func:`vbgs.components.parse_components`)."""
    from vbgs.components import parse_components  # plain Python

    if not isinstance(value, str):
        return None
    try:
        parse_components(value)
    except ValueError:
        return ("must be an integer (without quotes), \"auto\" or \"auto:MAX\" "
                "(MAX a positive integer)")
    return None


def _splat_scale(value) -> str | None:
    return None if valid_splat_scale(value) else "must be a positive number or \"auto\""


def _sensor_level(value) -> str | None:
    if not (math.isfinite(value) and value >= 0):
        return "must be a finite number >= 0 (0: exact depth values, 1: the published model)"
    return None


def _size(value) -> str | None:
    """The problem :func:`vbgs.data.scene.parse_size` finds in a size, or None."""
    from vbgs.data.scene import parse_size  # imported here, as in _replay

    try:
        parse_size(value)
    except ValueError as err:
        return str(err)
    return None


@dataclass(frozen=True)
class Spec:
    """What values a setting accepts."""

    types: tuple[type, ...]
    doc: str
    choices: tuple = ()
    minimum: int | None = None
    check: Callable[[Any], str | None] | None = None  # returns a problem, or None


_INT, _STR = (int,), (str,)
SETTINGS: dict[str, Spec] = {
    "task": Spec(_STR, "which task runs the cell", tuple(TASKS)),
    "dataset": Spec(_STR, "photo name, synthetic scene (object, room, walk) or a dataset path"),
    "method": Spec(_STR, METHOD.help, METHOD.values),
    "size": Spec((int, str), "image side in pixels, or a scene's frames as \"WxH\" "
                 "(\"640x480\"; a list would be a grid of sizes)", check=_size),
    "components": Spec((int, str), "mixture components: the capacity K, or \"auto\" / "
                       "\"auto:MAX\" (chosen from the data, at most MAX)",
                       minimum=1, check=_components),
    "iters": Spec(_INT, "CAVI iterations of a batch image fit", minimum=1),
    "init": Spec(_STR, "component initialisation (data, random: oracle starts on a stream)",
                 INIT.values),
    "seed": Spec(_INT, "random seed", minimum=0),
    "stream": Spec(_STR, STREAM.help, STREAM.values),
    "order": Spec(_STR, ORDER.help, ORDER.values),
    "assign": Spec(_STR, ASSIGN.help, ASSIGN.values),
    "patch": Spec(_INT, "patch side for image patch streams", minimum=1),
    "reassign": Spec((bool, str), "re-seed unused components (auto: batch fits only)",
                     (True, False, "auto")),
    "replay": Spec(_STR, "replay buffer of the gradient baseline", check=_replay),
    "estep": Spec(_STR, ESTEP.help, ESTEP.values),
    "frames": Spec(_INT, "frames streamed from a scene", minimum=1),
    "format": Spec(_STR, FORMAT.help, FORMAT.values),
    "protocol": Spec(_STR, PROTOCOL.help, PROTOCOL.values),
    "opacity_rule": Spec(_STR, OPACITY_RULE.help, OPACITY_RULE.values),
    "colour_rule": Spec(_STR, COLOUR_RULE.help, COLOUR_RULE.values),
    "depth_kind": Spec(_STR, DEPTH_KIND.help, DEPTH_KIND.values),
    "steps_per_frame": Spec(_INT, "optimisation steps per streamed frame", minimum=1),
    "steps": Spec(_INT, "optimisation steps", minimum=1),
    "depth_model": Spec(_STR, "\"sensor\" depth, or an .onnx model estimating it",
                        check=_depth_model),
    "simulate_sensor": Spec(_STR, SENSOR.help, SENSOR.values),
    "sensor_level": Spec((float,), "noise multiplier of the simulated sensor",
                         check=_sensor_level),
    "sensor_holes": Spec(_STR, SENSOR_HOLES_HELP, check=_sensor_holes),
    "sensor": Spec(_STR, MEASURED_BY.help, MEASURED_BY.values),
    "poses": Spec(_STR, POSES.help, POSES.values),
    "splat_scale": Spec((float, str), "VBGS splat covariance scale (sigma multiplier), or "
                        "\"auto\" (chosen on the arrived training frames)", check=_splat_scale),
}
TOP_LEVEL = ("name", "description", "fixed", "grid")


@dataclass(frozen=True)
class Grid:
    """One grid: each key with its tuple of values (fixed values merged in)."""

    axes: tuple[tuple[str, tuple], ...]

    def as_dict(self) -> dict[str, tuple]:
        return dict(self.axes)


@dataclass(frozen=True)
class SweepConfig:
    name: str
    description: str
    grids: tuple[Grid, ...]
    source: str  # the file it came from, for messages and provenance


def _type_name(types: tuple[type, ...]) -> str:
    return " or ".join({int: "an integer", str: "a string", bool: "true/false",
                        float: "a number"}.get(t, t.__name__) for t in types)


def _is(value, types: tuple[type, ...]) -> bool:
    if isinstance(value, bool):  # TOML true is not an integer here
        return bool in types
    if float in types and isinstance(value, int):
        return True
    return isinstance(value, types)


def _task_fields() -> dict[str, Any]:
    """Field name -> default value over every task whose module is importable."""
    out = {}
    for kind in TASKS.values():
        try:
            fields = kind.fields() if kind.available() else {}
        except TaskUnavailable:  # refused later, and only if a grid uses that task
            fields = {}
        for name, f in fields.items():
            out.setdefault(name, f.default)
    return out


def _nested_spec(key: str) -> Spec | None:
    """A dotted setting of a task's nested config (``evidence.forget_after``), checked
    by its default's type; None when ``key`` names none."""
    for kind in TASKS.values():
        try:
            default = nested_default(kind.name, key) if kind.available() else None
        except (KeyError, TaskUnavailable):
            continue
        return Spec((type(default),) if default is not None else (), "nested setting")
    return None


def _flatten(table: dict, prefix: str = "") -> dict:
    """A TOML table with the dotted settings it holds as nested tables
    (``evidence.forget_after = 0`` reads as ``{"evidence": {"forget_after": 0}}``) made
    flat again: ``{"evidence.forget_after": 0}``; a table under any other key is left for
    the value checks to refuse."""
    flat = {}
    for key, value in table.items():
        name = prefix + key
        if isinstance(value, dict) and (prefix or name in _nested_heads()):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def _nested_heads() -> set[str]:
    """The task fields that hold a nested config (``evidence``, ``growth``, ...)."""
    heads = set()
    for kind in TASKS.values():
        try:
            fields = kind.fields() if kind.available() else {}
        except TaskUnavailable:
            continue
        heads.update(name for name, f in fields.items() if is_dataclass(field_default(f)))
    return heads


def _spec_for(key: str, where: str, extra: dict[str, Any]) -> Spec:
    if key in SETTINGS:
        return SETTINGS[key]
    if "." in key and (spec := _nested_spec(key)) is not None:
        return spec
    if key in extra:  # a task field the table above does not know: check by its default
        default = extra[key]
        types = (type(default),) if default not in (None, MISSING) else ()
        return Spec(types, "task field")
    known = sorted(set(SETTINGS) | set(extra))
    hint = difflib.get_close_matches(key, known, n=1)
    raise ConfigError(f"{where}: unknown key {key!r}"
                      + (f" (did you mean {hint[0]!r}?)" if hint else "")
                      + f"; known settings: {', '.join(known)}")


def _check_value(key: str, value, spec: Spec, where: str) -> None:
    if spec.types and not _is(value, spec.types):
        raise ConfigError(f"{where}: must be {_type_name(spec.types)}, got {value!r}")
    if spec.choices and value not in spec.choices:
        raise ConfigError(f"{where}: must be one of {', '.join(map(str, spec.choices))}, "
                          f"got {value!r}")
    if spec.minimum is not None and not isinstance(value, str) and value < spec.minimum:
        what = "positive" if spec.minimum == 1 else f">= {spec.minimum}"
        raise ConfigError(f"{where}: must be a {what} integer, got {value!r}")
    if spec.check is not None and (problem := spec.check(value)):
        raise ConfigError(f"{where}: {problem}, got {value!r}")


def _values(raw, where: str) -> tuple:
    values = tuple(raw) if isinstance(raw, list) else (raw,)
    if not values:
        raise ConfigError(f"{where}: an empty list gives no cells; give at least one value")
    if isinstance(raw, dict) or any(isinstance(v, (list, dict)) for v in values):
        raise ConfigError(f"{where}: must be a value or a flat list of values, got {raw!r}")
    if len(set(map(repr, values))) != len(values):
        raise ConfigError(f"{where}: repeats a value in {raw!r}")
    return values


def _check_datasets(axes: dict[str, tuple], where: str) -> None:
    """Each dataset must be a built-in name of a task in the grid, or an existing path
    (pairs of a task with another task's built-in dataset are skipped by the rules)."""
    kinds = [TASKS[task] for task in axes["task"]]
    for dataset in axes["dataset"]:
        if not any(kind.dataset_exists(dataset) for kind in kinds):
            names = "; ".join(f"{k.name}: {', '.join(k.dataset_names())}" for k in kinds)
            raise ConfigError(f"{where}.dataset: {dataset!r} is neither a built-in dataset "
                              f"({names}) nor an existing path")


def parse_config(data: dict, source: str = "<config>") -> SweepConfig:
    """Validate a parsed TOML document and freeze it."""
    for key in data:
        if key not in TOP_LEVEL:
            raise ConfigError(f"{source}: unknown top-level key {key!r}; expected "
                              f"{', '.join(TOP_LEVEL)}")
    name = data.get("name")
    if not isinstance(name, str) or not name.strip() or "/" in name:
        raise ConfigError(f"{source}: name: must be a non-empty string without '/', "
                          f"got {name!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ConfigError(f"{source}: description: must be a string, got {description!r}")
    fixed = data.get("fixed", {})
    if not isinstance(fixed, dict):
        raise ConfigError(f"{source}: fixed: must be a table ([fixed]), got {fixed!r}")
    grids = data.get("grid")
    if not isinstance(grids, list) or not grids or not all(isinstance(g, dict) for g in grids):
        raise ConfigError(f"{source}: grid: give at least one [[grid]] table")
    fixed, grids = _flatten(fixed), [_flatten(g) for g in grids]
    extra = _task_fields()
    for key, value in fixed.items():
        where = f"{source}: fixed.{key}"
        if isinstance(value, (list, dict)):
            raise ConfigError(f"{where}: [fixed] takes single values; put lists in a [[grid]]")
        _check_value(key, value, _spec_for(key, where, extra), where)
    frozen = []
    for i, grid in enumerate(grids):
        axes = {key: (value,) for key, value in fixed.items()}
        for key, raw in grid.items():
            where = f"{source}: grid[{i}].{key}"
            spec = _spec_for(key, where, extra)
            axes[key] = _values(raw, where)
            for value in axes[key]:
                _check_value(key, value, spec, where)
        for required in ("task", "dataset"):
            if required not in axes:
                raise ConfigError(f"{source}: grid[{i}]: missing key {required!r} "
                                  "(set it in the grid or in [fixed])")
        for task in axes["task"]:
            try:
                TASKS[task].load()
            except TaskUnavailable as err:
                raise ConfigError(f"{source}: grid[{i}].task: {err}") from None
        _check_datasets(axes, f"{source}: grid[{i}]")
        frozen.append(Grid(tuple(axes.items())))
    return SweepConfig(name=name, description=description, grids=tuple(frozen), source=source)


def load_config(path: str | Path) -> SweepConfig:
    """Read and validate a sweep config file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"sweep config {str(path)!r} does not exist")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None
    return parse_config(data, str(path))
