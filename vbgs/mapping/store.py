"""A map saved to one file and loaded again: a robot's map survives a restart, and a
stream resumed from a saved state learns what the uninterrupted stream would have.

:func:`save` writes every array of a :class:`vbgs.mapping.MapState` (the mixture's prior,
posterior and statistics, the opacity evidence, the colour sums, the growth tables, the
random key) into one ``.npz`` file beside a small JSON schema of the state's structure,
written atomically (:mod:`vbgs.io_atomic`), so a run killed while saving leaves the
previous file whole. The compiled stepper is not pickled: :func:`load` builds it again
for the loaded reference (as the first frame of a stream would) and then puts back the
saved E-step terms, padded size and tiling, so the resumed stream computes with the
same numbers in the same shapes as the uninterrupted one: equal to the bit, not only
close (``tests/vbgs/mapping/test_store.py``).

Only classes of this package are rebuilt from a file's schema; nothing in it is
executed, and arrays are read without pickle.
"""

from __future__ import annotations

import dataclasses
import importlib
import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from vbgs.inference import projective
from vbgs.io_atomic import atomic_path
from vbgs.inference.stepper import Stepper
from vbgs.mapping.config import Config
from vbgs.mapping.mapper import MapState, _sync_stepper

FORMAT = 4  # bumped when the file's layout changes (3: the change doubt's colour and weight;
#            4: its colour runs, counted apart under a colour gate)
_SCHEMA = "__schema__"


def save(path, state: MapState) -> Path:
    """Write ``state`` to ``path`` (``.npz`` is added when missing); returns the path."""
    if state.unjudged:
        raise ValueError("the map's last frame is not settled (update(..., defer=True)): "
                         "save vbgs.mapping.settled(state, config)")
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_name(path.name + ".npz")
    arrays: dict[str, np.ndarray] = {}
    schema = {"format": FORMAT, "state": _pack(state, "s", arrays)}
    arrays[_SCHEMA] = np.array(json.dumps(schema))
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)
    return path


def load(path, config: Config) -> MapState:
    """The :class:`MapState` saved at ``path``, ready for the next frame under ``config``
    (the config it was learned with: its shapes and settings are not in the file)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"no saved map at {path}: write one with "
                                "vbgs.mapping.save(path, state)")
    with np.load(path, allow_pickle=False) as data:
        try:
            schema = json.loads(str(data[_SCHEMA]))
        except KeyError:
            raise ValueError(f"{path} is not a saved map (no schema inside)") from None
        if schema.get("format") != FORMAT:
            raise ValueError(f"{path} is a saved map of format {schema.get('format')}; "
                             f"this version reads format {FORMAT}")
        arrays = {name: data[name] for name in data.files}
    state = _unpack(schema["state"], arrays)
    saved = state.stepper
    state = state._replace(stepper=None)
    if saved is None or state.mixture is None:
        return state
    search = saved.get("search") or config.search  # maps saved before it was kept
    state = _sync_stepper(state, np.zeros(0, np.int64), config,
                          "projective" if search == "projective" else "kdtree")
    step = state.stepper
    if saved["reference"] is not None and step.fixed is not None:
        step.fixed = step.fixed._replace(reference=saved["reference"])
    step.size = int(saved["size"])
    step.tiling = None if saved["tiling"] is None else projective.Tiling(*saved["tiling"])
    return state


def _pack(value, name: str, arrays: dict) -> dict:
    """The schema node of ``value``, its arrays stored in ``arrays`` under ``name...``."""
    if value is None:
        return {"none": True}
    if isinstance(value, Stepper):
        fixed = value.fixed
        return {"stepper": {
            "reference": None if fixed is None else _pack(fixed.reference, name + ".r", arrays),
            "size": int(value.size),
            "search": value.search,
            "tiling": None if value.tiling is None else list(value.tiling)}}
    if isinstance(value, jax.Array) and jnp.issubdtype(value.dtype, jax.dtypes.prng_key):
        arrays[name] = np.asarray(jax.random.key_data(value))
        return {"key": name, "impl": str(jax.random.key_impl(value))}
    fields = _record_fields(value)
    if fields is not None:
        cls = type(value)
        if not cls.__module__.startswith("vbgs."):
            raise TypeError(f"cannot save a {cls.__module__}.{cls.__qualname__} in a map")
        return {"type": f"{cls.__module__}:{cls.__qualname__}",
                "fields": {f: _pack(getattr(value, f), f"{name}.{f}", arrays)
                           for f in fields}}
    if isinstance(value, tuple | list):
        return {"list": [_pack(v, f"{name}.{i}", arrays) for i, v in enumerate(value)]}
    if isinstance(value, str):
        return {"value": value, "kind": "str"}
    if isinstance(value, jax.Array | np.ndarray):
        arrays[name] = np.asarray(value)
        return {"array": name, "device": isinstance(value, jax.Array)}
    if isinstance(value, bool | int | float | np.integer | np.floating):
        kind = "bool" if isinstance(value, bool) else "int" if isinstance(
            value, int | np.integer) else "float"
        return {"value": value.item() if hasattr(value, "item") else value, "kind": kind}
    raise TypeError(f"cannot save a {type(value).__name__} in a map ({name})")


def _record_fields(value) -> tuple[str, ...] | None:
    """The field names of a record (a NamedTuple, or a frozen dataclass such as the
    prior's config), rebuilt by keyword; None for anything else."""
    if isinstance(value, tuple) and hasattr(value, "_fields"):
        return value._fields
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return tuple(f.name for f in dataclasses.fields(value))
    return None


def _unpack(node: dict, arrays: dict):
    if node.get("none"):
        return None
    if "stepper" in node:
        saved = dict(node["stepper"])
        ref = saved["reference"]
        saved["reference"] = None if ref is None else _unpack(ref, arrays)
        return saved
    if "key" in node:
        return jax.random.wrap_key_data(jnp.asarray(arrays[node["key"]]), impl=node["impl"])
    if "type" in node:
        module, qualname = node["type"].split(":")
        if not module.startswith("vbgs."):
            raise ValueError(f"a saved map names the class {node['type']}, not one of vbgs")
        cls = importlib.import_module(module)
        for part in qualname.split("."):
            cls = getattr(cls, part)
        return cls(**{f: _unpack(v, arrays) for f, v in node["fields"].items()})
    if "list" in node:
        return tuple(_unpack(v, arrays) for v in node["list"])
    if "array" in node:
        a = arrays[node["array"]]
        return jnp.asarray(a) if node["device"] else a
    return {"bool": bool, "int": int, "float": float, "str": str}[node["kind"]](node["value"])
