"""``write-scene``: a synthetic scene written as a dataset folder, a simulated sensor's
depth on its training frames only (test and validation views exact: the truth a run
is scored against).

The frames are those ``fit-scene --scene NAME --simulate-sensor S`` learns from in
memory: the same scene (:func:`experiments.tasks.scene_task.load_task_scene`) and the same
simulation (:func:`experiments.tasks.sensor_swap.simulate_training_depth`, frame ``i``'s
noise from ``[seed, SENSOR_STREAM, i]``). The folder records the sensor
(:mod:`vbgs.data.sensor_record`), so ``fit-scene --scene FOLDER`` takes its
measurement model by default. What the files keep (:func:`vbgs.data.blender.write_blender`):

* colour: 8 bits a channel (rounded to 1/255: at most 1/510 off, train and held-out);
* depth: 16-bit millimetres (at most 0.5 mm off; a hole, 0, stays a hole), or where
  some frame's depth lies beyond their 65.535 units (a depth network's sky on the
  walk) float32 ``.npy`` files, exact;
* cameras: intrinsics and poses as JSON floats (float64, read back exactly; the
  OpenGL axis flip is exact).

Measured at fit-scene's defaults with a Kinect (results/sensors/folder): the folder
against memory, object -0.029 dB, room +0.038 dB. At an earlier code, where the room's
folder scored -0.030 dB against memory, the in-memory frames with colour rounded to 8
bits alone scored -0.005 dB, depth rounded to 1 mm alone -0.008, both -0.030 (the
folder's figure to 0.0005 dB; one-off runs, no results file): the gap is the rounding,
felt through a growing map's order-dependent choices, not a camera or split mismatch.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from experiments.progress import progress as progress_bar
from experiments.tasks.scene_task import SceneTask, load_task_scene
from experiments.tasks.sensor_swap import simulate_training_depth
from vbgs.data.blender import depth_files, write_blender
from vbgs.data.scene import size_text
from vbgs.data.sensor_record import SENSOR_RECORD, write_sensor_record
from vbgs.data.synthetic import SCENES
from vbgs.sensors import check_level

WRITERS = {"blender": write_blender}  # layouts with train, test and val splits of their own


def check_out(out, force: bool) -> Path:
    """The folder to write: new, empty, or (``force``) one whose files of the same
    names are replaced; a file, or a non-empty folder without ``force``, is refused."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} is a file; give a folder to write the dataset into")
    if out.is_dir() and any(out.iterdir()) and not force:
        n = sum(1 for _ in out.iterdir())
        raise ValueError(f"--out {out} is not empty ({n} entries); give a new folder, or "
                         f"--force to write into it (files of the same names are replaced)")
    return out


def valid_level(level) -> bool:
    """A well-formed sensor level (a malformed one is refused with its own message)."""
    try:
        check_level(level)
    except ValueError:
        return False
    return True


def write_scene(scene: str, out, *, size=128, frames: int = 60, n_test: int = 8,
                n_val: int = 4, seed: int = 0, sensor: str = "exact", level: float | None = None,
                holes: str = "sensor", format: str = "blender", force: bool = False,
                progress: bool = False) -> dict:
    """Write synthetic ``scene`` to folder ``out`` in ``format``, sensor ``sensor``'s
    depth (at ``level``, with ``holes``) on its training frames; return the record:
    the folder, what was written, and the sensor report fit-scene gives in memory."""
    if scene not in SCENES:
        raise ValueError(f"write-scene writes a synthetic scene ({', '.join(SCENES)}); "
                         f"{scene!r} is not one (a dataset folder is read as it is)")
    if format not in WRITERS:
        raise ValueError(f"unknown --format {format!r}: write-scene writes "
                         f"{', '.join(WRITERS)} (a layout with its own test and val splits)")
    if not isinstance(n_test, int) or n_test < 1:
        raise ValueError(f"--test-views must be at least 1 (the views a run is scored on), "
                         f"got {n_test!r}")
    if not isinstance(n_val, int) or n_val < 1:
        raise ValueError(f"--val-views must be at least 1, got {n_val!r}: without a "
                         f"validation split the loader holds every 8th training frame out "
                         f"for validation, and the folder's stream would be shorter than "
                         f"the scene's")
    if level is not None and sensor == "exact" and valid_level(level):
        raise ValueError(f"--sensor-level {level:g} scales a simulated sensor's noise, and "
                         f"--simulate-sensor exact has none (the folder would record the "
                         f"level for every later run): give --simulate-sensor "
                         f"kinect|realsense|mono with it, or drop it")
    task = SceneTask(scene=scene, size=size, frames=frames, n_test=n_test, n_val=n_val,
                     seed=seed, simulate_sensor=sensor,
                     sensor_level=level,
                     sensor_holes=holes, sensor="exact")  # checks the settings
    out = check_out(out, force)
    start = time.perf_counter()
    print(f"rendering the {scene} scene ({size_text(task.size)}, {frames} training, "
          f"{n_test} test, {n_val} validation views) ...", file=sys.stderr, flush=True)
    data, report = simulate_training_depth(load_task_scene(task), sensor, task.sensor_level,
                                           seed, holes)
    out.mkdir(parents=True, exist_ok=True)
    splits = {"train": sensor, "test": "exact", **({"val": "exact"} if data.val else {})}
    write_sensor_record(out, sensor, task.sensor_level, holes, seed, splits,
                        f"write-scene --scene {scene} --size {size_text(task.size)} "
                        f"--seed {seed}", report)  # first: a folder cut short has no transforms

    def bar(items, total):
        return progress_bar(items, total=total, desc="frames written", unit="frame",
                            enabled=progress, compiles=False)

    files = depth_files(data)
    WRITERS[format](data, out, progress=bar, depth=files)
    kept = ("depth at 1 mm (16-bit PNGs): the folder's frames differ from the in-memory ones "
            "by at most 1/510 and 0.5 mm" if files == "png" else
            "depth exactly (float32 .npy: some depth lies beyond the 65.535 units a 16-bit "
            "millimetre PNG holds): the folder's colour differs by at most 1/510")
    print(f"note: colour is stored at 8 bits and {kept}", file=sys.stderr)
    return {"out": str(out), "format": format, "scene": scene, "size": size_text(task.size),
            "frames": len(data.train), "n_test": len(data.test), "n_val": len(data.val),
            "seed": seed, "sensor_holes": holes, "depth_files": files,
            "sensor_record": str(out / SENSOR_RECORD),
            **report, "seconds": time.perf_counter() - start}
