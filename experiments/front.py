"""Run time and memory against error: the whole front (``python -m experiments.run front``).

For a scene (``--scene``) every point is one ``fit-scene`` run at the same size,
components and frames:

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
forgetting, :mod:`experiments.protocol`) and ``on_front``: on the Pareto front of PSNR against wall time (no other row
is at least as fast and at least as good, and better in one). Written as CSV and
markdown (:func:`experiments.bench.write_table`) and one PNG: PSNR against wall time
(log scale), the front drawn, and PSNR against replay memory. Wall times are the
runs' own training seconds on this machine without compilation: for a scene,
``seconds - seconds_compiling`` of ``fit-scene``'s record (VBGS-polish: VBGS's stream
plus the polish; JAX reports the tracing of a function compiled inside another within
the outer's too, so a little more than the compilation may be taken off); for an image,
each fit runs twice and the second, warm, run is timed (fits are cheap).
``compile_seconds`` says what was left out.
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


def scene_tasks(base, plan: FrontPlan) -> list:
    """The :class:`experiments.scene_task.SceneTask` of each row, ``base`` giving the
    scene, size, components, frames and seed."""
    from dataclasses import replace

    tasks = [replace(base, method="vbgs")]
    tasks += [replace(base, method="vbgs-polish", protocol="static", steps=n)
              for n in plan.polish_steps]
    tasks += [replace(base, method="gradient", protocol="static", init="data", steps=n)
              for n in plan.gradient_steps]
    if plan.continual:
        for spec in plan.replays:
            tasks += [replace(base, method=m, protocol="continual", replay=spec,
                              steps_per_frame=plan.steps_per_frame)
                      for m in ("gradient", "vbgs-polish")]
    for task in tasks:  # bad settings fail before any run
        from experiments.learners import LEARNERS

        LEARNERS[task.method].check(task)
    return tasks


def scene_row(task, record: dict) -> dict:
    """One CSV row from a task and its ``fit-scene`` record."""
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


def _say(i: int, n: int, row: dict) -> None:
    print(f"front [{i}/{n}] {row['method']} {row['protocol']} steps={row['steps']} "
          f"replay={row['replay']}: {row['psnr']:.2f} dB in {row['wall_seconds']:.1f} s",
          file=sys.stderr, flush=True)


def run_scene_front(base, plan: FrontPlan) -> list[dict]:
    """Every row of a scene's front (progress on stderr)."""
    from experiments.scene_task import run_scene

    tasks = scene_tasks(base, plan)
    rows = []
    for i, task in enumerate(tasks, 1):
        print(f"front [{i}/{len(tasks)}] running {task.method} {task.protocol} ...",
              file=sys.stderr, flush=True)
        rows.append(scene_row(task, run_scene(task).to_dict(images=False)))
        _say(i, len(tasks), rows[-1])
    return mark_front(rows)


def run_image_front(image: str, size: int, components: tuple[int, ...], iters: int,
                    gradient_steps: tuple[int, ...], seed: int = 0) -> list[dict]:
    """VBGS's batch fit and the 2-D gradient baseline at each step count, for each
    component count, each fit timed warm (progress on stderr)."""
    from experiments.image_task import ImageTask, run_image

    tasks = []
    for k in components:
        tasks.append(ImageTask(image=image, size=size, components=k, iters=iters, seed=seed))
        tasks += [ImageTask(image=image, size=size, components=k, seed=seed,
                            method="gradient", steps=n) for n in gradient_steps]
    rows = []
    for i, task in enumerate(tasks, 1):
        cold = run_image(task)["seconds"]  # compiles; the second run is timed warm
        record = run_image(task)
        compiled = max(0.0, cold - record["seconds"])
        rows.append({"method": task.method, "protocol": "image", "init": task.init,
                     "components": task.components,
                     "steps": task.iters if task.method == "vbgs" else task.steps,
                     "replay": "none", "wall_seconds": record["seconds"],
                     "compile_seconds": compiled, "replay_bytes": 0,
                     "psnr": record["psnr"], "ssim": record["ssim"],
                     "depth_l1": float("nan"), "early_psnr_when_seen": float("nan"),
                     "early_psnr_at_end": float("nan"), "dropped": 0})
        _say(i, len(tasks), rows[-1])
    return mark_front(rows)


def pareto(cost: np.ndarray, score: np.ndarray) -> np.ndarray:
    """``[n]`` bool: rows no other row dominates (cost at most and score at least as
    good, one of them strictly)."""
    cost, score = np.asarray(cost, float), np.asarray(score, float)
    better = ((cost[None, :] <= cost[:, None]) & (score[None, :] >= score[:, None])
              & ((cost[None, :] < cost[:, None]) | (score[None, :] > score[:, None])))
    return ~better.any(axis=1)


def mark_front(rows: list[dict]) -> list[dict]:
    """``rows`` with ``on_front`` (PSNR against wall time, :func:`pareto`)."""
    on = pareto([r["wall_seconds"] for r in rows], [r["psnr"] for r in rows])
    return [{**r, "on_front": bool(f)} for r, f in zip(rows, on, strict=True)]


def label(row: dict) -> str:
    """The legend name of a row's series: method, protocol and replay buffer."""
    if row["protocol"] == "continual" and row["method"] != "vbgs":
        return f"{row['method']} continual {row['replay']}"
    return f"{row['method']} {row['protocol']}"


def plot_front(rows: list[dict], path: Path, title: str) -> None:
    """PSNR against wall time (log x; the front drawn as a step line) and, beside it,
    PSNR against replay memory."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator

    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(12, 4.6))
    series: dict[str, list[dict]] = {}
    for r in rows:
        series.setdefault(label(r), []).append(r)
    markers = "osD^v<>PX*"
    for j, (name, rs) in enumerate(series.items()):
        rs = sorted(rs, key=lambda r: r["wall_seconds"])
        kw = dict(marker=markers[j % len(markers)], label=name)
        ax_t.plot([r["wall_seconds"] for r in rs], [r["psnr"] for r in rs], **kw)
        for r in rs:
            if r["steps"]:
                ax_t.annotate(str(r["steps"]), (r["wall_seconds"], r["psnr"]), fontsize=7,
                              textcoords="offset points", xytext=(3, 3))
        ax_m.plot([r["replay_bytes"] / 2**20 for r in rs], [r["psnr"] for r in rs],
                  linestyle="none", **kw)
    front = sorted((r for r in rows if r["on_front"]), key=lambda r: r["wall_seconds"])
    ax_t.step([r["wall_seconds"] for r in front], [r["psnr"] for r in front], where="post",
              color="black", linewidth=2.5, alpha=0.35, label="Pareto front", zorder=0)
    ax_t.set_xscale("log")
    plain = FuncFormatter(lambda x, _: f"{x:g}")  # 0.2, 0.5, 1, 2, 5, 10, ...
    ax_t.xaxis.set_minor_locator(LogLocator(subs=(2.0, 5.0)))
    ax_t.xaxis.set_major_formatter(plain)
    ax_t.xaxis.set_minor_formatter(plain)
    ax_t.set_xlabel("wall seconds (training; log scale)")
    ax_m.set_xscale("symlog", linthresh=0.01)
    ax_m.set_xlabel("replay memory (MiB of frames held; symlog)")
    for ax in (ax_t, ax_m):
        ax.set_ylabel("held-out PSNR (dB)")
        ax.grid(alpha=0.3, which="both")
    handles, names = ax_t.get_legend_handles_labels()
    fig.legend(handles, names, fontsize=8, loc="upper center", bbox_to_anchor=(0.5, 0.0),
               ncol=min(4, len(names)), frameon=False)
    fig.suptitle(title + " (labels: steps)")
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png"))
    plt.close(fig)


def write_front(rows: list[dict], out: str | Path, name: str, *, command: str, title: str
                ) -> list[Path]:
    """``name.csv``, ``name.md`` and ``name.png`` under ``out``."""
    from experiments.bench import write_table

    ordered = [{k: r[k] for k in (*COLUMNS, "on_front")} for r in rows]
    note = ("on_front: on the Pareto front of held-out PSNR against wall seconds. Wall "
            "times are training seconds on this machine (shared CPUs are contended).")
    paths = write_table(ordered, out, name, command=command, note=note)
    png = Path(out) / f"{name}.png"
    plot_front(rows, png, title)
    return [*paths, png]
