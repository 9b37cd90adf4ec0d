"""Sweeps end to end: local/serial/Dask backends, resuming, failures, --force, report."""

import csv
import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from experiments.provenance import is_stamped_json, is_stamped_markdown
from experiments.run import main
from experiments.sweep.cells import cell_path, failed_record, stored_keys, store_record
from experiments.sweep.tasks import TASKS

FIGURES = ("psnr_vs_components.png", "psnr_vs_seconds.png", "renders.png")
METRICS = ("psnr", "ssim", "components_used", "elbo")


def _toml(path: Path, name: str, body: str) -> Path:
    path.write_text(f'name = "{name}"\n[fixed]\ntask = "image"\nsize = 16\niters = 2\n'
                    + body)
    return path


def _sweep(*args, **kw):
    return subprocess.run([sys.executable, "-m", "experiments.run", "sweep", *args],
                          capture_output=True, text=True, timeout=300, **kw)


def _records(out: Path) -> dict:
    return {k: json.loads(cell_path(out, k).read_text()) for k in stored_keys(out)}


def _rows(out: Path) -> list[dict]:
    with open(out / "cells.csv") as f:
        return list(csv.DictReader(f))


def test_local_backend_two_workers_end_to_end(tmp_path):
    config = _toml(tmp_path / "c.toml", "e2e", '[[grid]]\ndataset = ["astronaut", "coffee"]\n'
                   'components = 20\ninit = "data"\nseed = [0, 1]\n')
    out = tmp_path / "res"
    # workers share JAX's persistent compilation cache (~/.cache/vbgs/jax), as for users
    run = _sweep("--config", str(config), "--out", str(out), "--workers", "2", "--json")
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout.strip().splitlines()[-1])
    assert summary["finished"] == 4 and summary["failed"] == 0 and summary["workers"] == 2
    assert summary["tables"] == str(out / "tables.md")
    rows = _rows(out)
    assert len(rows) == 4 and {r["status"] for r in rows} == {"ok"}
    assert len({r["pid"] for r in rows}) == 2, "both worker processes should have run cells"
    assert str(os.getpid()) not in {r["pid"] for r in rows}
    if len(os.sched_getaffinity(0)) >= 2:  # each worker pinned to a core of its own
        assert len({r["cpus"] for r in rows}) == 2 and all(" " not in r["cpus"] for r in rows)
    tables = (out / "tables.md").read_text()
    assert "PSNR (dB)" in tables and "astronaut" in tables and "± " in tables
    assert is_stamped_markdown(tables) and "experiments.run sweep --config" in tables
    assert is_stamped_json(json.loads((out / "plan.json").read_text()))
    cells = list(_records(out).values())
    assert len(cells) == 4 and all(is_stamped_json(c) for c in cells)
    for name in FIGURES:
        assert (out / name).stat().st_size > 5_000, name
    assert len(list((out / "renders").glob("*.png"))) == 8  # render + target per cell
    log = (out / "sweep.log").read_text()
    assert log.count("| ok ") == 4 and "pid" in log


def test_report_on_a_results_folder(tmp_path, capsys):
    config = _toml(tmp_path / "c.toml", "rep", '[[grid]]\ndataset = "coffee"\n'
                   'components = 20\ninit = "data"\nseed = [0, 1]\n')
    out = tmp_path / "res"
    assert main(["sweep", "--config", str(config), "--out", str(out),
                 "--backend", "serial"]) == 0
    for name in ("cells.csv", "tables.md", *FIGURES):
        (out / name).unlink()
    # one cell as a worker that died leaves it: no result, no timing, no worker fields
    key, record = sorted(_records(out).items())[0]
    store_record(out, failed_record(key, record["settings"], "worker process 7 died", ""))
    capsys.readouterr()
    assert main(["report", str(out), "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert result["cells"] == 2 and result["ok"] == 1 and result["failed"] == 1
    assert "worker process 7 died" in (out / "tables.md").read_text()
    assert any("forgetting" in note for note in result["notes"])
    for name in ("cells.csv", "tables.md", *FIGURES):
        assert (out / name).is_file(), name
    assert "skipped: no cell reports a `forgetting_curve`" in (out / "tables.md").read_text()
    assert main(["report", str(tmp_path / "nothing")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_killed_sweep_resumes_without_recomputing(tmp_path):
    # two component counts: the second cell compiles anew (seconds), so the kill lands
    # while it is in flight; the same shapes as other in-process tests keep the rest fast
    body = '[[grid]]\ndataset = "astronaut"\ncomponents = [20, 30]\ninit = "data"\n'
    config = _toml(tmp_path / "c.toml", "resume", body)
    out = tmp_path / "res"
    proc = subprocess.Popen([sys.executable, "-m", "experiments.run", "sweep", "--config",
                             str(config), "--out", str(out), "--backend", "serial"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    deadline = time.monotonic() + 240
    while not stored_keys(out) and time.monotonic() < deadline:
        assert proc.poll() is None, "sweep ended before the first cell was stored"
        time.sleep(0.02)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    before = {k: (out / "cells" / f"{k}.json").stat().st_mtime_ns for k in _records(out)}
    assert len(before) == 1, "the kill should land while the second cell is in flight"

    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--no-report"]) == 0
    for key, mtime in before.items():
        assert (out / "cells" / f"{key}.json").stat().st_mtime_ns == mtime, "recomputed"
    clean = tmp_path / "clean"
    assert main(["sweep", "--config", str(config), "--out", str(clean),
                 "--backend", "serial", "--no-report"]) == 0
    _assert_same_results(out, clean, n=2)


def _assert_same_results(out: Path, reference: Path, n: int) -> None:
    resumed, fresh = _records(out), _records(reference)
    assert resumed.keys() == fresh.keys() and len(fresh) == n
    for key in fresh:
        assert resumed[key]["status"] == fresh[key]["status"] == "ok"
        a, b = resumed[key]["result"], fresh[key]["result"]
        for metric in METRICS:
            assert a[metric] == pytest.approx(b[metric], rel=1e-5), (key, metric)


def test_failed_cell_is_recorded_and_the_sweep_goes_on(tmp_path, capsys):
    photo = tmp_path / "photo.png"
    photo.write_bytes(b"not a png at all")  # the injected failure: an unreadable image
    config = _toml(tmp_path / "c.toml", "fail", f'[[grid]]\ndataset = ["{photo}", '
                   '"astronaut"]\ncomponents = 20\ninit = "data"\nseed = [0, 1]\n')
    out = tmp_path / "res"
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["finished"] == 2 and summary["failed"] == 2
    records = _records(out)
    failed = [r for r in records.values() if r["status"] == "failed"]
    assert len(failed) == 2 and "could not read image file" in failed[0]["error"]
    assert "Traceback (most recent call last)" in failed[0]["traceback"]
    assert {r["status"] for r in _rows(out)} == {"ok", "failed"}
    assert "could not read image file" in next(r for r in _rows(out)
                                               if r["status"] == "failed")["error"]
    assert "## Failed cells" in (out / "tables.md").read_text()
    assert (out / "sweep.log").read_text().count("| failed ") == 2

    # fix the input and run again: only the failed cells run; the result is complete
    # and the same as a sweep that never failed
    ok = {k: (out / "cells" / f"{k}.json").stat().st_mtime_ns
          for k, r in records.items() if r["status"] == "ok"}
    from matplotlib.image import imsave

    from vbgs.data.images import load_image

    imsave(photo, load_image("coffee", 16))
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--json", "--no-report"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (summary["reused"], summary["finished"], summary["failed"]) == (2, 2, 0)
    assert all((out / "cells" / f"{k}.json").stat().st_mtime_ns == t for k, t in ok.items())
    clean = tmp_path / "clean"
    assert main(["sweep", "--config", str(config), "--out", str(clean),
                 "--backend", "serial", "--no-report"]) == 0
    _assert_same_results(out, clean, n=4)

    # --force recomputes finished cells too
    capsys.readouterr()
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--force", "--json", "--no-report"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["reused"] == 0 and summary["finished"] == 4
    assert all((out / "cells" / f"{k}.json").stat().st_mtime_ns != t for k, t in ok.items())


def test_max_cells_then_the_rest(tmp_path, capsys):
    config = _toml(tmp_path / "c.toml", "max", '[[grid]]\ndataset = "astronaut"\n'
                   'components = 20\ninit = "data"\nseed = [0, 1, 2]\n')
    out = tmp_path / "res"
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--max-cells", "1", "--json", "--no-report"]) == 0
    assert not (out / "tables.md").exists()
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (summary["finished"], summary["not_run"]) == (1, 2)
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert (summary["finished"], summary["reused"], summary["not_run"]) == (2, 1, 0)


def test_dask_backend_on_a_local_cluster(tmp_path, capsys):
    distributed = pytest.importorskip("dask.distributed")
    config = _toml(tmp_path / "c.toml", "dask", '[[grid]]\ndataset = "astronaut"\n'
                   'components = 20\ninit = "data"\nseed = [0, 1]\n')
    out = tmp_path / "res"
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        assert main(["sweep", "--config", str(config), "--out", str(out), "--backend",
                     "dask", "--scheduler", cluster.scheduler_address, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["finished"] == 2 and summary["failed"] == 0
    assert {r["status"] for r in _rows(out)} == {"ok"}
    assert (out / "tables.md").is_file()


def test_dask_backend_needs_a_scheduler(tmp_path, capsys):
    config = _toml(tmp_path / "c.toml", "dask", '[[grid]]\ndataset = "astronaut"\n'
                   'components = 20\n')
    assert main(["sweep", "--config", str(config), "--out", str(tmp_path / "res"),
                 "--backend", "dask"]) == 2
    assert "--backend dask needs --scheduler" in capsys.readouterr().err
    assert not (tmp_path / "res").exists()


FAKE_SCENE = '''
from dataclasses import dataclass
import numpy as np


@dataclass(frozen=True)
class SceneTask:
    scene: str = "object"
    method: str = "vbgs"
    replay: str = "none"
    components: int = 100
    assign: str = "prior"
    seed: int = 0
    frames: int = 4


def run_scene(task, progress=False):
    drop = 0.0 if task.method == "vbgs" else (1.0 if task.replay == "none" else 0.3)
    base = 20 + task.components / 100 + task.seed * 0.1
    return {"psnr": base, "ssim": 0.9, "depth_l1": 0.05, "seconds": 0.01,
            "forgetting_curve": [[i, base - drop * i] for i in range(1, task.frames + 1)],
            "images": {"target": np.zeros((8, 8, 3)), "render": np.full((8, 8, 3), 0.5)}}
'''


def test_scene_cells_through_a_stand_in_scene_task(tmp_path, monkeypatch, capsys):
    """Scene dispatch, the gradient/replay rules, depth tables and forgetting curves,
    with a stand-in module in place of experiments.tasks.scene_task."""
    (tmp_path / "fake_scene_task.py").write_text(FAKE_SCENE)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(TASKS, "scene", dataclasses.replace(TASKS["scene"],
                                                            module="fake_scene_task"))
    config = tmp_path / "c.toml"
    config.write_text('name = "scene"\n[fixed]\nsize = 16\niters = 2\n[[grid]]\n'
                      'task = ["scene", "image"]\ndataset = ["object", "coffee"]\n'
                      'method = ["vbgs", "gradient"]\nreplay = ["none", "fifo:4"]\n'
                      'assign = ["prior", "posterior"]\ncomponents = 20\n'
                      'seed = [0, 1]\n')  # one component count (20, as the other sweeps here)
    out = tmp_path / "res"
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    # scene/object: (vbgs x assign(2) + gradient x replay(2)) x seed(2);
    # image/coffee: (vbgs + gradient), no replay, batch fit (no assign) x seed(2)
    assert summary["finished"] == 8 + 4 and summary["failed"] == 0
    rows = _rows(out)
    assert {(r["task"], r["dataset"]) for r in rows} == {("scene", "object"),
                                                          ("image", "coffee")}
    assert all(r["size"] == "" for r in rows if r["task"] == "scene")  # not a scene field
    assert not any(r["method"] == "vbgs" and r["replay"] not in ("", "none") for r in rows)
    assert all(r["assign"] == "" for r in rows if r["method"] == "gradient")
    tables = (out / "tables.md").read_text()
    assert "depth L1" in tables and "replay buffers belong to the gradient" in tables
    assert "another task's built-in dataset" in tables
    assert (out / "forgetting.png").stat().st_size > 5_000


# a real scene task's cells through the serial backend, scored and reported, run by
# test_robustness_study.py::test_a_tiny_study_end_to_end in the default suite (three
# cells of 32 px object scenes); this one cell took 9.5 s of CPU in the default run
@pytest.mark.slow
def test_real_scene_cell(tmp_path, capsys):
    config = tmp_path / "c.toml"
    # render-bound's, tune's and colour-gap's tiny shapes (16 px, 3 frames, 150
    # components): the learner they compiled
    config.write_text('name = "scene"\n[[grid]]\ntask = "scene"\ndataset = "object"\n'
                      'size = 16\nframes = 3\ncomponents = 150\nseed = 0\n')
    out = tmp_path / "res"
    assert main(["sweep", "--config", str(config), "--out", str(out), "--backend", "serial",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["failed"] == 0, (out / "sweep.log").read_text()
    assert "psnr" in _rows(out)[0]
