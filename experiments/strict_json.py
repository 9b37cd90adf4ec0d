"""Strict JSON out of every command: a number that is not finite (a PSNR of +inf when the
render equals its target, NaN where nothing was measured) becomes ``null`` with a reason
beside it (``"psnr": null, "psnr_note": "..."``), so strict parsers (JavaScript's
``JSON.parse``, ``jq``) read every line. :func:`dumps` is the one writer.
"""

from __future__ import annotations

import json
import math

import numpy as np


def _plain(value):
    """numpy and jax scalars and arrays as Python numbers and lists; the rest unchanged."""
    if isinstance(value, np.generic):
        return value.item()
    if not isinstance(value, (str, bytes, dict, list, tuple)) and hasattr(value, "__array__"):
        return np.asarray(value).tolist()
    return value


def _why(key: str, value: float) -> str:
    if math.isnan(value):
        return "not a number (NaN): nothing to measure it on in this run"
    sign = "+" if value > 0 else "-"
    if value > 0 and "psnr" in key.lower():
        return "+infinity: zero error, the render equals its target exactly"
    return f"{sign}infinity: the quantity has no finite value in this run"


def _bad(value) -> bool:
    return isinstance(value, float) and not math.isfinite(value)


def sanitise(value, key: str = ""):
    """``value`` with every non-finite float ``null`` and, in a dict, a ``<key>_note``
    saying why (for a list: which entries)."""
    value = _plain(value)
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            v = _plain(v)
            if _bad(v):
                out[k], out[f"{k}_note"] = None, _why(str(k), v)
                continue
            if isinstance(v, (list, tuple)):
                bad = [i for i, x in enumerate(v) if _bad(_plain(x))]
                if bad:
                    out[f"{k}_note"] = (f"entries {', '.join(map(str, bad[:8]))} are null: "
                                        f"{_why(str(k), float(_plain(v[bad[0]])))}")
            out[k] = sanitise(v, str(k))
        return out
    if isinstance(value, (list, tuple)):
        return [None if _bad(_plain(v)) else sanitise(v, key) for v in value]
    return value


def dumps(value, **kw) -> str:
    """Strict JSON of ``value`` (:func:`sanitise` first; unknown types as ``str``)."""
    return json.dumps(sanitise(value), allow_nan=False, default=str, **kw)
