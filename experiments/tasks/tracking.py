"""Tracked streams (``fit-scene --poses track|odometry``): the learner is fed each frame
at the pose the tracker finds against its own map, not at the true one.

:class:`TrackedLearner` wraps a learner that can ``locate(frame, guess, config, seed)``
(VBGS: :meth:`experiments.learners.vbgs_learner.VbgsLearner.locate`) and is itself a
:class:`experiments.tasks.protocol.Learner`, so the stream protocol, its timing and its
scores are unchanged: ``learn`` registers the frame (the first pose is given: it
fixes the map's frame), then learns it at the estimated pose; its seconds count in
the run's ``seconds_per_frame``. The guess for frame ``i`` is

* ``track``: constant velocity, ``P_i-1 (P_i-2^-1 P_i-1)``; for the second frame the
  first pose, registered with the wider start :data:`vbgs.tracking.register.BOOTSTRAP`
  (with photometric refinement on, that registration or one of :data:`SEARCH`'s
  motions from the first pose, whichever the map's splats rendered explain best:
  :meth:`TrackedLearner.search`);
* ``odometry``: the odometry's measured motion applied to the previous estimate,
  ``P_i-1 (O_i-1^-1 O_i)``, the odometry drifting by ``--drift`` per frame
  (:mod:`vbgs.tracking.drift`; the true poses feed only this simulated sensor).

With :data:`DIRECT` (the default) that motion is first refined by the direct RGB-D
odometry from the frame before (:mod:`vbgs.tracking.direct`; for the second frame of a
track, from the best of :data:`SEARCH`'s motions), and the map registration starts from
it. Where the registration leaves directions free (:mod:`vbgs.tracking.degeneracy`):
on a planar frame the pose is the odometry's whole (on the walk under a Kinect the
registration against a map of the near road moved the forward and vertical position
by 2-3 mm a frame the wrong way, ATE 7.9 cm; the odometry's pose on its planar frames
11.6 mm); otherwise the registration's pose is kept (on the object under a Kinect the
chained odometry alone drifted to 3.7 cm ATE; the registration from its starts 1.2 cm). Either way the free directions' ``pose_sigmas`` are the chained
odometry's (its step's covariance added frame by frame), the frames are listed in
``tracking_degenerate_frames`` (numbered from 1, the given first) and said on stderr.

With :data:`PHOTOMETRIC` on and measured depth (a sensor other than ``exact``) each
registered pose of a frame with little depth is then refined photometrically against
the map's splats (:func:`photo_config`, :mod:`vbgs.tracking.photometric`); it is off
by default (the measurements at :data:`PHOTOMETRIC`).

Test views keep their true poses: the map's frame is the first camera's, which is
given, so renders need no alignment; the trajectory metrics
(:mod:`vbgs.tracking.trajectory`) use the standard one.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace

import numpy as np

from experiments.tasks.protocol import COMPILE_FRAMES, task_sensor
from experiments.tasks.settings import POSES
from vbgs.data.scene import Frame, Scene
from vbgs.io_atomic import write_atomic
from vbgs.render.camera import valid_depth
from vbgs.tracking import direct, drift, trajectory
from vbgs.tracking.degeneracy import describe, fuse
from vbgs.tracking.photometric import PhotoConfig
from vbgs.tracking.register import BOOTSTRAP, TrackConfig
from vbgs.tracking.se3 import hat, inverse, orthonormalise, relative, se3_exp


def check_poses(task) -> None:
    """Refuse pose settings a tracked stream cannot run, in one line each."""
    POSES.check("poses", task.poses)
    drift.parse_drift(task.drift)
    if task.poses == "given":
        return
    flag = f"--poses {task.poses}"
    if task.method != "vbgs":
        raise ValueError(f"{flag} registers frames against the VBGS posterior: use "
                         f"--method vbgs (the gradient baseline learns given poses only)")
    if task.order != "sequential":
        raise ValueError(f"{flag} needs the frames in temporal order (each guess comes from "
                         f"the frames before): use --order sequential, not {task.order!r}")
    if task.init != "stream":
        raise ValueError(f"{flag} needs --init stream: init {task.init!r} starts the map "
                         f"from every training frame at its true pose")


def _search_grid() -> np.ndarray:
    """Camera-frame motions ``[m, 6]`` tried for the second frame: forward (z) -1..1
    and sideways (x) -0.5..0.5 scene units in steps of 0.25, no rotation."""
    z, x = np.meshgrid(np.arange(-4, 5) * 0.25, np.arange(-2, 3) * 0.25)
    out = np.zeros((z.size, 6))
    out[:, 0], out[:, 2] = x.ravel(), z.ravel()
    return out


SEARCH = _search_grid()


# A frame is refined photometrically only where fewer than this share of its pixels
# have depth: the room under a Kinect keeps depth nearly everywhere (the geometric
# tracker alone: 4.9 mm), the walk under it about a third (the near road).
PHOTO_BELOW = 0.5


# Whether tracked tasks with measured depth refine photometrically by default: not yet.
# On the walk under a Kinect (128 px, 20k, 60 frames) it lifted the track from lost at
# the second frame (ATE 9.40 units) only to lost after about ten (8.24 units, 0.78 s a
# frame against 0.18 with given poses), and it pulled the odometry-guided track from
# 7.7 cm to 5.86 units: the map's splats, learned from the sensor's banded near road,
# rendered from the next pose do not look enough like the frame (module docstring of
# vbgs.tracking.photometric). :func:`photo_config` and the search stay for that work.
PHOTOMETRIC = False


def photo_config(task) -> PhotoConfig | None:
    """The photometric refinement a tracked task runs after the geometric registration:
    with :data:`PHOTOMETRIC`, where the depth is measured (``task.sensor`` not
    ``exact``), and then only on frames with depth on under :data:`PHOTO_BELOW` of their
    pixels; None (geometric registration only) otherwise.

    Decided on the training streams: with exact depth the geometric tracker alone is
    within 0.2 mm on the object and the room and 1.5 mm on the walk (results/tracking),
    so the refinement could only cost time; a sensor's range and holes leave the walk's
    depth one near plane (the geometric tracker alone lost it from the second frame:
    ATE 9.4 units), where the colours should carry the motion along it.
    """
    if not PHOTOMETRIC or task_sensor(task).exact:
        return None
    return PhotoConfig()


# Whether a tracked stream starts each frame from the direct RGB-D odometry from the
# frame before (vbgs.tracking.direct) and takes the directions the map registration
# leaves free from it (vbgs.tracking.degeneracy.fuse).
DIRECT = True


def _ranges(numbers: list[int]) -> str:
    """``[2, 3, 4, 7]`` -> ``'2-4, 7'``."""
    out, start = [], None
    for i, n in enumerate(numbers):
        start = n if start is None else start
        if i + 1 == len(numbers) or numbers[i + 1] != n + 1:
            out.append(str(n) if n == start else f"{start}-{n}")
            start = None
    return ", ".join(out)


# The map registration after the odometry: its start is near, so one level, the map as
# it is, one pass. Its points and Levenberg-Marquardt steps: the setting with the lowest
# summed ATE over the tracking study's nine tracked streams on validation trajectories
# (seed 1, never the reported seed 0; results/tuning/tracking/tracking.md, made by
# python -m experiments.tune_tracking): 2048 points and 6 steps were better than 1024 and 4
# on every stream, and on eight of the nine (24.10 against 33.60 mm summed) when the table
# was re-made at a later code. The cost bound (results/tracking/cost/) is
# measured at these settings.
AFTER_DIRECT = dict(levels=(2048,), inflate=(0.0,), passes=(1,), iterations=6)


def _finite(x: float) -> float | None:
    """``x``, or None (JSON null) when it is not finite."""
    return float(x) if np.isfinite(x) else None


def _adjoint(pose: np.ndarray) -> np.ndarray:
    """The ``[6, 6]`` adjoint of a rigid transform on twists ``(v, w)``."""
    rot, t = pose[:3, :3], pose[:3, 3]
    out = np.zeros((6, 6))
    out[:3, :3], out[3:, 3:] = rot, rot
    out[:3, 3:] = hat(t) @ rot
    return out


class TrackedLearner:
    """A learner fed estimated poses (module docstring)."""

    def __init__(self, learner, task, scene: Scene, config: TrackConfig = TrackConfig(),
                 photo: PhotoConfig | None | str = "task"):
        self.inner, self.mode, self.config, self.seed = learner, task.poses, config, task.seed
        if getattr(learner, "pipelined", False):  # each frame registers against the
            learner.pipelined = False  # settled map: its frame's own time, not tracking's
        self.photo = photo_config(task) if photo == "task" else photo
        self.odometry = None
        if self.mode == "odometry":
            truth = np.stack([f.camera.pose for f in scene.train])
            self.odometry = drift.odometry(truth, *drift.parse_drift(task.drift), seed=task.seed)
        self.truth: list[np.ndarray] = []
        self.estimates: list[np.ndarray] = []
        self.sigmas: list[list[float]] = []  # per registered frame: |sigma_t|, |sigma_r| (deg)
        self.seconds: list[float] = []  # registration time per registered frame
        # the direct odometry from the frame before (None: the map registration alone)
        # (with the photometric refinement on, its own search and refinement instead)
        self.direct = direct.DirectConfig() if DIRECT and self.photo is None else None
        self.pyramid: direct.Pyramid | None = None  # the last frame's, for the odometry
        self.covariance = np.zeros((6, 6))  # the last pose's (right twist)
        # (frame number from 1, why, which directions) of each frame with free directions
        self.free: list[tuple[int, str, str]] = []

    replay_bytes = property(lambda self: self.inner.replay_bytes)
    blur = property(lambda self: self.inner.blur)

    def splats(self, drop_unused: bool = False):
        return self.inner.splats(drop_unused)

    def diagnose(self, frame: Frame) -> None:
        hook = getattr(self.inner, "diagnose", None)
        if hook is not None:
            hook(frame)

    def guess(self) -> np.ndarray:
        """The next frame's starting pose (module docstring)."""
        motion, last = self.motion_guess(), self.estimates[-1]
        return last if motion is None else orthonormalise(last @ motion)

    def search(self, frame: Frame, guess, config: TrackConfig, background) -> np.ndarray:
        """The second frame's start with photometric refinement on: the geometric
        registration (:data:`BOOTSTRAP`) or one of :data:`SEARCH` motions from the first
        pose, whichever the map's splats rendered at it explain best."""
        geometric = self.inner.locate(frame, guess, config, seed=self.seed + 1).pose
        starts = np.concatenate([geometric[None], guess @ se3_exp(SEARCH)])
        costs = self.inner.photo_costs(frame, starts, self.photo, background)
        return starts[int(np.argmin(costs))]

    def motion_guess(self) -> np.ndarray | None:
        """The motion from the last frame to the next one (module docstring); None for
        the second frame of a track (no velocity yet)."""
        i = len(self.estimates)
        if self.odometry is not None:
            return relative(self.odometry[i - 1], self.odometry[i])
        if i >= 2:
            return relative(self.estimates[-2], self.estimates[-1])
        return None

    def _pyramid(self, frame: Frame) -> direct.Pyramid:
        return direct.pyramid(frame.camera, frame.rgb, frame.depth, self.direct.factors)

    def _direct(self, frame: Frame) -> direct.Motion:
        """The direct RGB-D odometry from the frame before (:mod:`vbgs.tracking.direct`),
        from the motion guess, or from :data:`SEARCH`'s motions for the second frame.
        Each frame's pyramid is built once: it is the previous frame of the next."""
        prev, guess = self.pyramid, self.motion_guess()
        new = self.pyramid = self._pyramid(frame)
        if guess is None:
            starts = se3_exp(np.concatenate([np.zeros((1, 6)), SEARCH]))
            return direct.search_pyramids(prev, new, starts, self.direct)
        return direct.align_pyramids(prev, new, guess, self.direct)

    def learn(self, frame: Frame, background) -> None:
        sparse = valid_depth(np.asarray(frame.depth)).mean() < PHOTO_BELOW
        photo = self.photo if sparse else None
        extra = {} if photo is None else {"photo": photo, "background": background}
        pose = np.asarray(frame.camera.pose, np.float64)  # the first: given
        cov = np.zeros((6, 6))
        if self.estimates:
            start = time.perf_counter()
            config, odo = self.config, None
            if self.direct is not None:
                odo = self._direct(frame)
                guess = orthonormalise(self.estimates[-1] @ odo.motion)
                config = replace(config, **AFTER_DIRECT)
            else:
                if self.odometry is None and len(self.estimates) == 1:  # no velocity yet
                    config = replace(config, **BOOTSTRAP)
                guess = self.guess()
                if photo is not None and self.odometry is None and len(self.estimates) == 1:
                    guess = self.search(frame, guess, config, background)
                    config = self.config  # the search's best start is near: the usual levels
            found = self.inner.locate(frame, guess, config,
                                      seed=self.seed + len(self.estimates), **extra)
            pose, cov = found.pose, None
            if odo is not None and photo is None:  # the free directions from the odometry
                info = self._chained(odo)
                if found.free.planar and found.free.free.shape[1]:  # a plane: all odometry
                    pose, cov = guess, np.linalg.pinv(info)
                else:
                    pose, cov = fuse(found.pose, found.hessian, found.free, None, info)
            self.seconds.append(time.perf_counter() - start)
            if cov is None:
                cov = np.diag(np.concatenate([found.sigma_t, np.radians(found.sigma_r_deg)])**2)
            if found.free.free.shape[1]:
                self.free.append((len(self.estimates) + 1, found.free.reason,
                                  describe(found.free.free)))
            sig = np.sqrt(np.abs(np.diag(cov)))
            self.sigmas.append([_finite(np.linalg.norm(sig[:3])),
                                _finite(np.degrees(np.linalg.norm(sig[3:])))])
        self.covariance = cov
        if self.direct is not None and self.pyramid is None:  # the first frame
            self.pyramid = self._pyramid(frame)
        self.truth.append(np.asarray(frame.camera.pose, np.float64))
        self.estimates.append(pose)
        moved = frame._replace(camera=frame.camera._replace(pose=pose))
        self.inner.learn(moved, background)

    def _chained(self, odo: direct.Motion) -> np.ndarray:
        """Information ``[6, 6]`` of the new pose by the odometry: its step's covariance
        plus the last pose's, carried along the step (``P exp(xi) M = P M exp(Ad(M^-1)
        xi)``), so a direction only the odometry fixes grows less sure frame by frame."""
        step = np.linalg.pinv(odo.hessian)
        prev = self.covariance
        if not np.all(np.isfinite(prev)):
            return np.zeros((6, 6))  # the last pose is unknown along some direction
        ad = _adjoint(inverse(odo.motion))
        return np.linalg.pinv(ad @ prev @ ad.T + step)

    def say_free(self) -> None:
        """Say on stderr, once a run, which frames had pose directions their depth left
        free, which directions (those free in at least half of them; else the most
        frequent) and what fixed them."""
        for reason in dict.fromkeys(r for _, r, _ in self.free):
            frames = [f for f, r, _ in self.free if r == reason]
            words = [w for f, r, d in self.free if r == reason for w in d.split(", ")]
            names = sorted(set(words), key=lambda w: (-words.count(w), words.index(w)))
            names = [w for w in names if 2 * words.count(w) >= len(frames)] or names[:1]
            if self.direct is None:
                then = ("poses there are the registration's from the motion model's guess "
                        "(pose_sigmas: null)")
            elif "planar" in reason:
                then = ("poses there are the direct RGB-D alignment's with the frame before "
                        "(pose_sigmas: its steps' added up frame by frame)")
            else:
                then = ("poses there keep the registration's estimate; pose_sigmas along "
                        "them are the direct RGB-D alignment's, added up frame by frame")
            print(f"warning: tracking, frames {_ranges(frames)} of {len(self.estimates)}: "
                  f"{' and '.join(names)}: {reason}; {then}", file=sys.stderr)

    def details(self, result) -> dict:
        """The inner learner's details and the trajectory's: ``ate_rmse``, ``rpe_trans``,
        ``rpe_rot_deg``, ``odometry_ate_rmse`` (odometry), ``tracking_seconds_per_frame``
        (compilation left out), per-frame ``pose_errors`` ([position, degrees]),
        ``pose_sigmas`` ([|sigma_t|, |sigma_r| degrees] of each registered frame) and
        the camera centres (``trajectory``: true, estimated, odometry)."""
        truth, est = np.stack(self.truth), np.stack(self.estimates)
        err = trajectory.errors(est, truth)
        steady = self.seconds[COMPILE_FRAMES:] or self.seconds or [0.0]
        out = {"ate_rmse": err.ate_rmse, "rpe_trans": err.rpe_trans,
               "rpe_rot_deg": err.rpe_rot_deg}
        paths = {"true": truth[:, :3, 3].tolist(), "estimated": est[:, :3, 3].tolist()}
        if self.odometry is not None:
            odo = self.odometry[: len(est)]
            out["odometry_ate_rmse"] = trajectory.errors(odo, truth).ate_rmse
            paths["odometry"] = odo[:, :3, 3].tolist()
        out["tracking_degenerate_frames"] = [f for f, _, _ in self.free]
        out["tracking_degenerate_directions"] = [d for _, _, d in self.free]
        self.say_free()
        out.update(tracking_seconds_per_frame=float(np.mean(steady)),
                   pose_errors=np.stack([err.trans, err.rot_deg], -1).tolist(),
                   pose_sigmas=self.sigmas, trajectory=paths)
        return {**self.inner.details(result), **out}


def save_trajectory_plot(path, result: dict, title: str) -> None:
    """Top view (x, y; the synthetic scenes' z is up) of the true, estimated and (with
    odometry) odometry camera centres of a tracked run's record."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 5))
    styles = {"true": ("k-", "true"), "estimated": ("C0.-", "tracked"),
              "odometry": ("C3--", "odometry")}
    for name, (style, label) in styles.items():
        if name in result["trajectory"]:
            xy = np.asarray(result["trajectory"][name])[:, :2]
            ax.plot(xy[:, 0], xy[:, 1], style, label=label, ms=3, lw=1)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.legend()
    ax.set_title(title, fontsize=9)
    write_atomic(path, lambda tmp: fig.savefig(tmp, dpi=110, bbox_inches="tight"))
    plt.close(fig)
