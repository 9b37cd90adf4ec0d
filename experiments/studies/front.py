"""Run time and memory against error: the whole front (``python -m experiments.run front``).

For a scene (``--scene``) every point is a ``fit-scene`` record at the same size,
components and frames (the static rows of a method: one run scored at each step count,
below):

* ``vbgs``: the conjugate stream (no step, no replay);
* ``vbgs-polish``, static: VBGS streams, then N steps on all training frames, for each
  N of ``polish_steps``;
* ``gradient``, static: N steps on all training frames for each N of ``gradient_steps``,
  from the data start (every frame's points: under the static protocol every frame is
  there from the start, so this reads nothing ahead);
* continual, for each replay buffer of ``replays``: ``gradient`` (stream start) and
  ``vbgs-polish``, ``steps_per_frame`` steps on each arriving frame and the buffer.

For an image (``--image``) VBGS's batch fit against the 2-D gradient baseline at each
step count, for each component count (where splats are far fewer than pixels).

Each row: method, protocol, steps, replay, wall seconds, replay bytes, PSNR, SSIM,
depth L1, the early views' PSNR when seen and at the end (continual rows: the
forgetting, :mod:`experiments.tasks.protocol`) and ``on_front``: on the Pareto front of PSNR
against wall time (no other row is at least as fast and at least as good, and better in
one). Written as CSV and markdown (:func:`experiments.benchmarks.bench.write_table`) and one PNG:
PSNR against wall time (log scale), the front drawn, and PSNR against replay memory.

**One run per static method.** The static rows of a method are one run to the largest
step count, scored at each count (:func:`experiments.tasks.scene_task.run_scene_checkpoints`;
images: :func:`experiments.tasks.image_task.gradient_image_path`). The learners' learning
rates and frame draws are functions of the step count alone (the baseline's
:class:`vbgs.baseline.Trainer`), so the row at N steps is what a run of N steps gives
(tests/experiments/test_front.py holds them equal). Its wall time is the **cumulative
training time to that count**; the scoring of the test views at the earlier counts is
left out (it is no part of training).

Wall times are the runs' own training seconds on this machine without compilation: for
a scene, ``seconds - seconds_compiling`` of ``fit-scene``'s record (VBGS-polish: VBGS's
stream plus the polish; JAX reports the tracing of a function compiled inside another
within the outer's too, so a little more than the compilation may be taken off); for an
image, VBGS's fit runs twice and the second, warm, run is timed, and the gradient fit
compiles on a one-step fit before the timed one. ``compile_seconds`` says what was left
out. Rows of one front ran on the same machine one after another, so their times compare
with one another; across fronts, and across machines or loads, they do not.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vbgs.io_atomic import write_atomic

COLUMNS = ("method", "protocol", "init", "components", "steps", "replay", "wall_seconds",
           "compile_seconds", "replay_bytes", "psnr", "ssim", "depth_l1",
           "early_psnr_when_seen", "early_psnr_at_end", "dropped")


@dataclass(frozen=True)
class FrontPlan:
    """What a front runs (module docstring)."""

    polish_steps: tuple[int, ...] = (30, 100, 300, 900)
    gradient_steps: tuple[int, ...] = (100, 300, 900, 3000)
    replays: tuple[str, ...] = ("none", "fifo:8")
    steps_per_frame: int = 20
    continual: bool = True

    def __post_init__(self):
        for name in ("polish_steps", "gradient_steps"):
            values = getattr(self, name)
            if any(not isinstance(n, int) or n < 1 for n in values):
                raise ValueError(f"{name.replace('_', '-')}: every step count must be a "
                                 f"positive integer, got {list(values)}")
        if not isinstance(self.steps_per_frame, int) or self.steps_per_frame < 1:
            raise ValueError(f"--steps-per-frame must be a positive integer, got "
                             f"{self.steps_per_frame!r}")


def parse_counts(text: str, flag: str) -> tuple[int, ...]:
    """``"10,20"`` -> ``(10, 20)``; an empty string -> ``()``; anything else refused."""
    parts = [p.strip() for p in str(text).split(",") if p.strip()]
    if not all(p.isdigit() and int(p) > 0 for p in parts):
        raise ValueError(f"{flag} takes positive integers separated by commas (e.g. 10,20), "
                         f"got {text!r}")
    return tuple(int(p) for p in parts)


def scene_runs(base, plan: FrontPlan) -> list[tuple]:
    """The runs of a scene's front: ``(task, checkpoints)`` with the
    :class:`experiments.tasks.scene_task.SceneTask` of each (``base`` giving the scene, size,
    components, frames and seed) and, for a static run, the step counts it is scored at
    (one run to the largest; None: one row)."""
    from dataclasses import replace

    from experiments.learners import LEARNERS

    runs = [(replace(base, method="vbgs"), None)]
    if plan.polish_steps:
        runs.append((replace(base, method="vbgs-polish", protocol="static",
                             steps=max(plan.polish_steps)), plan.polish_steps))
    if plan.gradient_steps:
        runs.append((replace(base, method="gradient", protocol="static", init="data",
                             steps=max(plan.gradient_steps)), plan.gradient_steps))
    if plan.continual:
        for spec in plan.replays:
            runs += [(replace(base, method=m, protocol="continual", replay=spec,
                              steps_per_frame=plan.steps_per_frame), None)
                     for m in ("gradient", "vbgs-polish")]
    for task, _ in runs:  # bad settings fail before any run
        LEARNERS[task.method].check(task)
    return runs


def scene_row(task, record: dict) -> dict:
    """One CSV row from a task and its ``fit-scene`` record (a static checkpoint's
    record: its step count and the training seconds to it)."""
    steps = {"vbgs": 0}.get(task.method, record.get("steps_total", 0))
    return {"method": task.method, "protocol": "continual" if task.method == "vbgs"
            else task.protocol, "init": task.init, "components": task.components,
            "steps": int(steps), "replay": task.replay if task.protocol == "continual"
            and task.method != "vbgs" else "none",
            "wall_seconds": record["seconds"] - record["seconds_compiling"],
            "compile_seconds": record["seconds_compiling"], "replay_bytes": record["replay_bytes"], "psnr": record["psnr"],
            "ssim": record["ssim"], "depth_l1": record["depth_l1"],
            **{k: nan_if_none(record[k]) for k in ("early_psnr_when_seen",
                                                   "early_psnr_at_end")},
            "dropped": record["dropped"]}


def nan_if_none(value) -> float:
    """A metric a protocol does not measure (None) as NaN, for the table."""
    return float("nan") if value is None else float(value)


def _say(row: dict) -> None:
    print(f"front: {row['method']} {row['protocol']} steps={row['steps']} "
          f"replay={row['replay']}: {row['psnr']:.2f} dB in {row['wall_seconds']:.1f} s",
          file=sys.stderr, flush=True)


def run_scene_front(base, plan: FrontPlan, *, progress: bool = False) -> list[dict]:
    """Every row of a scene's front (:func:`scene_runs`; each row said on stderr, and with
    ``progress`` a bar over the runs and each run's own)."""
    from experiments.progress import progress as progress_bar
    from experiments.tasks.scene_task import run_scene, run_scene_checkpoints

    runs = scene_runs(base, plan)
    rows = []
    bar = progress_bar(runs, desc="front runs", unit="run", enabled=progress)
    for task, checkpoints in bar:
        if checkpoints is None:
            results = [run_scene(task, progress=progress)]
        else:
            results = (r for _, r in run_scene_checkpoints(task, checkpoints,
                                                           progress=progress))
        for result in results:
            rows.append(scene_row(task, result.to_dict(images=False)))
            _say(rows[-1])
    return mark_front(rows)


def _image_row(task, record: dict, compiled: float) -> dict:
    return {"method": task.method, "protocol": "image", "init": task.init,
            "components": task.components, "steps": record["iters"]
            if task.method == "vbgs" else record["steps"], "replay": "none",
            "wall_seconds": record["seconds"], "compile_seconds": compiled,
            "replay_bytes": 0, "psnr": record["psnr"], "ssim": record["ssim"],
            "depth_l1": float("nan"), "early_psnr_when_seen": float("nan"),
            "early_psnr_at_end": float("nan"), "dropped": 0}


def run_image_front(image: str, size: int, components: tuple[int, ...], iters: int,
                    gradient_steps: tuple[int, ...], seed: int = 0, *,
                    progress: bool = False) -> list[dict]:
    """VBGS's batch fit and the 2-D gradient baseline at each step count, for each
    component count (each row said on stderr; ``progress``: a bar over the fits and
    each gradient fit's own). Fits are timed warm: VBGS's runs twice, the second timed;
    the gradient's compiles on a one-step fit (its seconds, an upper bound of the
    compilation, are the first row's ``compile_seconds``), then one fit to the largest
    step count is scored at each (:func:`experiments.tasks.image_task.gradient_image_path`:
    seconds to each count, the scoring of the earlier ones left out)."""
    from experiments.tasks.image_task import ImageTask, gradient_image_path, run_image
    from experiments.progress import progress as progress_bar

    counts = sorted(set(gradient_steps))
    rows = []
    for k in progress_bar(components, desc="front components", unit="K", enabled=progress):
        task = ImageTask(image=image, size=size, components=k, iters=iters, seed=seed)
        cold = run_image(task)["seconds"]  # compiles; the second run is timed warm
        record = run_image(task)
        rows.append(_image_row(task, record, max(0.0, cold - record["seconds"])))
        _say(rows[-1])
        if not counts:
            continue
        task = ImageTask(image=image, size=size, components=k, seed=seed, method="gradient",
                         steps=counts[-1])
        (warm_up,) = gradient_image_path(task, (1,))  # compiles: one step and a render
        for record in gradient_image_path(task, counts, progress=progress):
            compiled = warm_up["seconds"] if record["steps"] == counts[0] else 0.0
            rows.append(_image_row(task, record, compiled))
            _say(rows[-1])
    return mark_front(rows)


def pareto(cost: np.ndarray, score: np.ndarray) -> np.ndarray:
    """``[n]`` bool: rows no other row dominates (cost at most and score at least as
    good, one of them strictly)."""
    cost, score = np.asarray(cost, float), np.asarray(score, float)
    better = ((cost[None, :] <= cost[:, None]) & (score[None, :] >= score[:, None])
              & ((cost[None, :] < cost[:, None]) | (score[None, :] > score[:, None])))
    return ~better.any(axis=1)


def front_cost(rows: list[dict]) -> list[float]:
    """Each row's wall time for the front: a VBGS-polish row contains a VBGS run of its
    component count, so it costs more than that run; a polish row timed at or under it
    (timing noise, or the compilation taken off) is said on stderr and costed just
    over it."""
    vbgs = {r["components"]: r["wall_seconds"] for r in rows if r["method"] == "vbgs"}
    cost = []
    for r in rows:
        inner = vbgs.get(r["components"]) if r["method"] == "vbgs-polish" else None
        if inner is not None and r["wall_seconds"] <= inner:
            print(f"warning: front: a vbgs-polish row ({r['steps']} steps) was timed at "
                  f"{r['wall_seconds']:.2f} s, under the {inner:.2f} s of the VBGS run it "
                  f"contains (timing noise); it is placed at {inner:.2f} s, so it cannot "
                  f"push VBGS off the front", file=sys.stderr)
            cost.append(float(np.nextafter(inner, np.inf)))
        else:
            cost.append(r["wall_seconds"])
    return cost


def mark_front(rows: list[dict]) -> list[dict]:
    """``rows`` with ``on_front`` (PSNR against wall time, :func:`front_cost`,
    :func:`pareto`; a row without a finite PSNR is on no front)."""
    psnr = np.array([np.nan if r["psnr"] is None else r["psnr"] for r in rows], float)
    measured = ~np.isnan(psnr)
    on = pareto(front_cost(rows), np.where(measured, psnr, -np.inf)) & measured
    return [{**r, "on_front": bool(f)} for r, f in zip(rows, on, strict=True)]


def label(row: dict) -> str:
    """The legend name of a row's series: method, protocol and replay buffer."""
    if row["protocol"] == "continual" and row["method"] != "vbgs":
        return f"{row['method']} continual {row['replay']}"
    return f"{row['method']} {row['protocol']}"


def reference_row(rows: list[dict]) -> dict | None:
    """The gradient baseline's static (or image) row with the most steps: the issue's
    yardstick (its PSNR, and a tenth of its wall time), drawn on the plot."""
    grad = [r for r in rows if r["method"] == "gradient" and r["protocol"] != "continual"]
    return max(grad, key=lambda r: (r["components"], r["steps"])) if grad else None


def plot_front(rows: list[dict], path: Path, title: str) -> None:
    """PSNR against wall time (log x; the front drawn as a thick grey step line, the
    gradient baseline's most-steps PSNR and a tenth of its time as dotted lines) and,
    beside it when there are streaming rows, their PSNR against replay memory (static
    rows hold every training frame: they have no place on a memory axis of a stream)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator

    streamed = [r for r in rows if r["protocol"] == "continual"]
    if streamed:
        fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(13, 5), width_ratios=(1.6, 1))
    else:  # an image's front: time alone
        fig, ax_t = plt.subplots(figsize=(8.5, 5))
        ax_m = None
    series: dict[str, list[dict]] = {}
    for r in rows:
        series.setdefault(label(r) + (f" K={r['components']}" if r["protocol"] == "image"
                                      else ""), []).append(r)
    markers = "osD^v<>PX*"
    for j, (name, rs) in enumerate(series.items()):
        rs = sorted(rs, key=lambda r: r["wall_seconds"])
        continual = rs[0]["protocol"] == "continual" and rs[0]["method"] != "vbgs"
        kw = dict(marker=markers[j % len(markers)], label=name, color=f"C{j % 10}",
                  linestyle="--" if continual else "-", markersize=6)
        ax_t.plot([r["wall_seconds"] for r in rs], [r["psnr"] for r in rs], **kw)
        for r in rs:
            if r["steps"]:
                ax_t.annotate(str(r["steps"]), (r["wall_seconds"], r["psnr"]), fontsize=7,
                              textcoords="offset points", xytext=(3, 3))
        if rs[0]["protocol"] == "continual":
            ax_m.plot([r["replay_bytes"] / 2**20 for r in rs], [r["psnr"] for r in rs],
                      **{**kw, "linestyle": "none"})
            for r in rs:
                drop = r["early_psnr_when_seen"] - r["early_psnr_at_end"]
                if np.isfinite(drop):
                    ax_m.annotate(f"early views, seen to end: {-drop:+.2f} dB",
                                  (r["replay_bytes"] / 2**20,
                                  r["psnr"]), fontsize=7, textcoords="offset points",
                                  xytext=(4, -10))
    front = sorted((r for r in rows if r["on_front"]), key=lambda r: r["wall_seconds"])
    ax_t.step([r["wall_seconds"] for r in front], [r["psnr"] for r in front], where="post",
              color="black", linewidth=6, alpha=0.18, label="Pareto front", zorder=0)
    ref = reference_row(rows)
    if ref is not None:
        ax_t.axhline(ref["psnr"], color="grey", linestyle=":", linewidth=1)
        ax_t.axvline(ref["wall_seconds"] / 10, color="grey", linestyle=":", linewidth=1)
        ax_t.annotate(f"gradient {ref['steps']} steps: {ref['psnr']:.2f} dB; "
                      f"dotted vertical: a tenth of its {ref['wall_seconds']:.0f} s",
                      (ref["wall_seconds"] / 10, ref["psnr"]), fontsize=7, color="dimgrey",
                      textcoords="offset points", xytext=(3, -11))
    ax_t.set_xscale("log")
    plain = FuncFormatter(lambda x, _: f"{x:g}")  # 0.2, 0.5, 1, 2, 5, 10, ...
    ax_t.xaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
    ax_t.xaxis.set_major_formatter(plain)
    ax_t.xaxis.set_minor_formatter(plain)
    ax_t.set_xlabel("wall seconds of training (log; static: cumulative to each step count)")
    ax_t.set_title("error against time (up and left is better; labels: steps)", fontsize=9)
    if ax_m is not None:
        ax_m.set_xscale("symlog", linthresh=0.01)
        ax_m.set_xlabel("replay memory (MiB of frames held; symlog)")
        ax_m.set_title("streaming learners: error against memory", fontsize=9)
    for ax in (ax_t, ax_m) if ax_m is not None else (ax_t,):
        ax.set_ylabel("held-out PSNR (dB)")
        ax.grid(alpha=0.3, which="both")
    handles, names = ax_t.get_legend_handles_labels()
    fig.legend(handles, names, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, 0.0),
               ncol=min(4, len(names)), frameon=False)
    fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png"))
    plt.close(fig)


def read_front(csv: str | Path) -> list[dict]:
    """A front's rows back from its CSV (``--replot``)."""
    import pandas as pd

    frame = pd.read_csv(csv, keep_default_na=False, na_values=[""])
    rows = frame.to_dict("records")
    for r in rows:
        r["replay"] = str(r["replay"])
        r["on_front"] = bool(r["on_front"])
    return rows


def write_front(rows: list[dict], out: str | Path, name: str, *, command: str, title: str
                ) -> list[Path]:
    """``name.csv``, ``name.md`` and ``name.png`` under ``out``."""
    from experiments.benchmarks.bench import write_table

    ordered = [{k: r[k] for k in (*COLUMNS, "on_front")} for r in rows]
    note = ("on_front: on the Pareto front of held-out PSNR against wall seconds. Wall "
            "times are training seconds on this machine (shared CPUs are contended), "
            "compilation left out; a static method's rows are one run scored at each step "
            "count, its wall seconds the cumulative training to that count (the scoring "
            "at earlier counts excluded).")
    paths = write_table(ordered, out, name, command=command, note=note,
                        settings={"title": title})
    png = Path(out) / f"{name}.png"
    plot_front(rows, png, title)
    return [*paths, png]
