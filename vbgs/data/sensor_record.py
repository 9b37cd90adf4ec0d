"""Which depth sensor measured a dataset's training depth: a folder's record, else the
format's default.

A folder written by ``python -m experiments.run write-scene`` carries
``depth_sensor.json``: the sensor simulated on its training frames (its level, holes
and seed, the splits it touched), so that ``fit-scene`` takes that sensor's
measurement model (``--sensor``) and level by default, and refuses to simulate a
second sensor on top of the first. Without a record the format says what it can:

* TUM RGB-D: ``kinect``: the benchmark was recorded with Microsoft Kinect v1 sensors
  (structured light, the model of :class:`vbgs.sensors.active.Kinect`);
* Replica, Blender: ``exact``: rendered depth.

A synthetic scene by name has no record and the ``exact`` default.
:func:`data_sensor` is the one place that decides.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

from vbgs.data.formats import detect_format
from vbgs.io_atomic import write_text_atomic
from vbgs.sensors import SENSOR_NAMES, check_level, parse_holes

SENSOR_RECORD = "depth_sensor.json"
# the sensor a format implies when its folder records none (module docstring)
FORMAT_SENSORS = {"tum": "kinect", "replica": "exact", "blender": "exact"}
DEFAULT_SENSOR = "exact"  # synthetic scenes, and a format that implies none


class DataSensor(NamedTuple):
    """The sensor that measured a scene's training depth, its noise level, where that
    was read (``sensor_from`` in a run's JSON) and whether a record said so."""

    sensor: str
    level: float
    source: str
    recorded: bool = False
    measured: dict = {}  # the record's share of holes and median error (flat report keys)


MEASURED_KEYS = ("depth_sensor_holes", "depth_sensor_abs_error")  # over the written frames


def write_sensor_record(folder, sensor: str, level: float, holes: str, seed: int,
                        splits: dict[str, str], source: str, measured: dict | None = None
                        ) -> Path:
    """Write ``folder/depth_sensor.json``: ``sensor`` at ``level`` with ``holes`` and
    ``seed`` on the splits ``splits`` names (``{"train": "kinect", "test": "exact"}``),
    ``source`` saying what was written (free text), ``measured`` the simulation's
    report (its :data:`MEASURED_KEYS` are kept: the share of the training pixels with
    depth that became holes, the median error). Returns the file's path."""
    if sensor not in SENSOR_NAMES:
        raise ValueError(f"unknown depth sensor {sensor!r}: use one of {', '.join(SENSOR_NAMES)}")
    record = {"sensor": sensor, "level": check_level(level), "holes": holes, "seed": int(seed),
              "splits": dict(splits), "source": source,
              "measured": {k: float(v) for k, v in (measured or {}).items()
                           if k in MEASURED_KEYS}}
    path = Path(folder) / SENSOR_RECORD
    write_text_atomic(path, json.dumps(record, indent=2) + "\n")
    return path


def read_sensor_record(folder) -> dict | None:
    """The record of ``folder`` (None when it has none), checked: a known sensor, a
    level >= 0 and a hole spec :func:`vbgs.sensors.parse_holes` reads; a malformed
    record is refused naming the file."""
    path = Path(folder) / SENSOR_RECORD
    if not path.is_file():
        return None
    try:
        record = json.loads(path.read_text())
        sensor, level = record["sensor"], record["level"]
        if sensor not in SENSOR_NAMES:
            raise ValueError(f"unknown sensor {sensor!r} (known: {', '.join(SENSOR_NAMES)})")
        check_level(level)
        parse_holes(record.get("holes", "sensor"))
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
        raise ValueError(f"{path}: not a depth-sensor record ({err}); it needs "
                         f"{{\"sensor\": NAME, \"level\": X}}; fix or delete it (fit-scene "
                         f"then takes the format's default sensor)") from None
    return record


def data_sensor(scene, format: str | None = None) -> DataSensor:
    """The sensor of ``scene`` (a dataset folder, or a synthetic scene's name): the
    folder's record, else its format's default, else ``exact``. ``format`` is the
    folder's layout (None: detected by :func:`vbgs.data.formats.detect_format`)."""
    path = Path(scene)
    if not path.is_dir():
        return DataSensor(DEFAULT_SENSOR, 1.0, "default (not a dataset folder)")
    record = read_sensor_record(path)
    if record is not None:
        measured = record.get("measured", {})
        return DataSensor(record["sensor"], float(record["level"]),
                          f"the folder's {SENSOR_RECORD}", recorded=True,
                          measured={k: measured[k] for k in MEASURED_KEYS if k in measured})
    if format is None:
        try:
            format = detect_format(path)
        except FileNotFoundError:  # the loader says what is missing
            return DataSensor(DEFAULT_SENSOR, 1.0, "default (format unknown)")
    sensor = FORMAT_SENSORS.get(format, DEFAULT_SENSOR)
    return DataSensor(sensor, 1.0, f"{format} default")
