"""Continual-learning metrics of a stream, as the literature reports them.

**Segments.** The training stream (the frames in the task's order) is cut into ``S``
consecutive segments of nearly equal length (:func:`segment_ends`; ``S`` is the task's
``cl_segments``). Segment ``j`` ends when ``ends[j]`` frames have been seen.

**A segment's views** ``V_j`` are the held-out *test* views nearest (camera centre,
Euclidean) to each of the segment's training cameras,
``V_j = { argmin_v ||c_v - c_f|| : f in segment j }`` (:func:`nearest_test_views`, the
rule the protocol's early views follow too). Every segment has at least one view; a view
nearest to cameras of two segments belongs to both. Camera centres alone decide: the
synthetic scenes' test views gaze within 0.5-0.8 rad of the heading of the path they sit
on, so where a view stands says what it sees. Test views only report: nothing here is
tuned on them.

**The matrix** ``R[i, j]`` (dB) is the mean PSNR over ``V_j`` after the frames of
segments ``0..i`` were learned (measured at ``ends[i]``, as the stream goes; the last row
is the final evaluation). On and below the diagonal (``j <= i``) segment ``j`` has been
seen; above it (``j > i``) its frames have not arrived yet: those entries are reported
(how much of a later segment the map already shows) but no metric below reads them.

* average final PSNR  ``A = 1/S * sum_j R[S-1, j]``
* forgetting (Chaudhry et al. 2018)
  ``F = 1/(S-1) * sum_{j<S-1} ( max_{i in [j, S-2]} R[i, j] - R[S-1, j] )``:
  how far each segment fell at the end from its best before the end (0: nothing
  forgotten; negative when the last segment improved every earlier one beyond its best,
  as a map that keeps filling in does)
* backward transfer (Lopez-Paz & Ranzato 2017)
  ``BWT = 1/(S-1) * sum_{j<S-1} ( R[S-1, j] - R[j, j] )``: how learning the later segments
  changed each segment against right after it was learned (< 0: forgetting, > 0: the
  later frames improved it)

Forward transfer is left out: it needs a reference score of each segment's views from a
learner that has seen nothing, which the stream protocol does not define.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from vbgs.data.scene import Scene

MIN_SEGMENTS = 2  # forgetting and backward transfer compare a segment with a later one


class Segments(NamedTuple):
    """The segments of one stream and the test views each is scored on."""

    ends: tuple[int, ...]  # [S] frames seen when segment j ends (the last: all frames)
    views: tuple[tuple[int, ...], ...]  # [S] test-view indices of segment j (V_j), sorted

    def views_at(self, step: int) -> list[int]:
        """The test views to render after ``step`` frames: every segment's views at an
        inner segment end, none elsewhere (the last row is the final evaluation's)."""
        if step not in self.ends[:-1]:
            return []
        return sorted({v for views in self.views for v in views})

    def row(self, view_psnr: dict[int, float]) -> list[float]:
        """One row of the matrix: the mean PSNR over each segment's views, from the PSNR
        of each test view rendered (by test-view index)."""
        return [float(np.mean([view_psnr[v] for v in views])) for views in self.views]


class ContinualScores(NamedTuple):
    """The matrix of one stream and the metrics read off it (see the module docstring)."""

    segments: Segments
    matrix: list[list[float]]  # R [S, S], dB: row i after segment i, column j segment j's views
    avg_final_psnr: float  # A, dB
    forgetting: float  # F, dB
    backward_transfer: float  # BWT, dB
    # seconds spent rendering and scoring at the inner segment ends (with the early views
    # where a forgetting-curve checkpoint falls on one: an upper bound on the matrix's cost)
    seconds: float

    def to_dict(self) -> dict:
        """The flat JSON fields, each named ``cl_*``."""
        return {"cl_segment_ends": list(self.segments.ends),
                "cl_segment_views": [list(v) for v in self.segments.views],
                "cl_matrix": self.matrix, "cl_avg_final_psnr": self.avg_final_psnr,
                "cl_forgetting": self.forgetting,
                "cl_backward_transfer": self.backward_transfer, "cl_seconds": self.seconds}


# The JSON fields of ContinualScores, None under the static protocol or cl_segments = 0.
FIELDS = ("cl_segment_ends", "cl_segment_views", "cl_matrix", "cl_avg_final_psnr",
          "cl_forgetting", "cl_backward_transfer", "cl_seconds")


def check_segments(n_segments: int, n_frames: int | None = None) -> None:
    """Refuse a segment count that is not 0 (no matrix) or 2 to ``n_frames``."""
    if not isinstance(n_segments, int) or isinstance(n_segments, bool) or n_segments < 0 \
            or 0 < n_segments < MIN_SEGMENTS:
        raise ValueError(f"cl_segments must be 0 (no continual-learning matrix) or an "
                         f"integer >= {MIN_SEGMENTS}, got {n_segments!r}")
    if n_frames is not None and n_segments > n_frames:
        raise ValueError(f"cl_segments {n_segments} is more than the {n_frames} training "
                         f"frames: each segment needs at least one frame")


def segment_ends(n_frames: int, n_segments: int) -> tuple[int, ...]:
    """Frames seen at the end of each of ``n_segments`` consecutive, nearly equal
    segments of a stream of ``n_frames`` (the first ``n_frames % n_segments`` one
    longer, as :func:`numpy.array_split` cuts)."""
    check_segments(n_segments, n_frames)
    sizes = [len(part) for part in np.array_split(np.arange(n_frames), n_segments)]
    return tuple(int(e) for e in np.cumsum(sizes))


def nearest_test_views(scene: Scene, frames) -> list[int]:
    """The test views nearest (camera centre) to each training frame in ``frames``
    (indices into ``scene.train``), sorted, each once."""
    train_pos = np.stack([scene.train[i].camera.position for i in frames])  # [f, 3]
    test_pos = np.stack([f.camera.position for f in scene.test])  # [v, 3]
    nearest = np.linalg.norm(test_pos[:, None] - train_pos[None], axis=-1).argmin(0)
    return sorted(set(int(i) for i in nearest))


def stream_segments(scene: Scene, order: np.ndarray, n_segments: int) -> Segments:
    """The ``n_segments`` segments of the stream ``order`` and their test views."""
    ends = segment_ends(len(order), n_segments)
    starts = (0, *ends[:-1])
    views = tuple(tuple(nearest_test_views(scene, order[a:b]))
                  for a, b in zip(starts, ends, strict=True))
    return Segments(ends, views)


def average_final_psnr(matrix) -> float:
    """``A = 1/S * sum_j R[S-1, j]``: the last row's mean."""
    return float(np.mean(np.asarray(matrix, dtype=np.float64)[-1]))


def forgetting(matrix) -> float:
    """``F = 1/(S-1) * sum_{j<S-1} (max_{i in [j, S-2]} R[i, j] - R[S-1, j])``
    (Chaudhry et al. 2018)."""
    r = np.asarray(matrix, dtype=np.float64)
    last = len(r) - 1
    return float(np.mean([r[j:last, j].max() - r[last, j] for j in range(last)]))


def backward_transfer(matrix) -> float:
    """``BWT = 1/(S-1) * sum_{j<S-1} (R[S-1, j] - R[j, j])`` (Lopez-Paz & Ranzato 2017)."""
    r = np.asarray(matrix, dtype=np.float64)
    last = len(r) - 1
    return float(np.mean([r[last, j] - r[j, j] for j in range(last)]))


def continual_scores(segments: Segments, matrix: list[list[float]], seconds: float
                     ) -> ContinualScores:
    """The record of one stream's matrix ``R [S, S]`` and the metrics read off it."""
    n = len(segments.ends)
    if np.shape(matrix) != (n, n):
        raise ValueError(f"the matrix of {n} segments must be {n} x {n}, got "
                         f"{np.shape(matrix)}")
    return ContinualScores(segments, [[float(x) for x in row] for row in matrix],
                           average_final_psnr(matrix), forgetting(matrix),
                           backward_transfer(matrix), float(seconds))
