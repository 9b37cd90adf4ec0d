import subprocess
import sys

import numpy as np
import onnx
import pytest
from skimage import io as skio

from depth.cli import PREVIEW_NAME, main
from depth.testing import depth_lookup_model
from vbgs.data.depth_png import read_depth_png, write_depth_png

N_FRAMES, H, W = 3, 24, 32
MM = 1000.0


@pytest.fixture
def scene(tmp_path):
    """3 uint8 frames on disk, their true depth (with a missing corner), and a folder."""
    rng = np.random.default_rng(0)
    rgb = (rng.random((N_FRAMES, H, W, 3)) * 255).astype(np.uint8)
    depth = rng.uniform(0.8, 4.0, (N_FRAMES, H, W)).astype(np.float32)
    depth[:, :3, :3] = 0.0
    frames = tmp_path / "frames"
    frames.mkdir()
    for i in range(N_FRAMES):
        skio.imsave(frames / f"frame_{i:02d}.png", rgb[i], check_contrast=False)
    return tmp_path, frames, rgb.astype(np.float32) / 255.0, depth


def _save(model, path):
    onnx.save(model, path)
    return str(path)


def test_metric_model_writes_millimetre_pngs_and_preview(scene, capsys):
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, 1.0, 0.0, space="depth"), tmp / "m.onnx")
    out = tmp / "out"
    assert main(["--model", model, "--input", str(frames), "--output", str(out),
                 "--kind", "metric", "--no-progress"]) == 0
    for i in range(N_FRAMES):
        raw = skio.imread(out / f"frame_{i:02d}.png")
        assert raw.dtype == np.uint16 and raw.shape == (H, W)
        np.testing.assert_array_equal(raw, np.round(depth[i] * MM).astype(np.uint16))
    assert (out / PREVIEW_NAME).stat().st_size > 0
    printed = capsys.readouterr().out
    assert f"{N_FRAMES} frames" in printed and "fps" in printed


def test_inverse_model_aligned_to_first_frame_reference(scene, capsys):
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, 2.0, 0.5, 1e-4, 0), tmp / "inv.onnx")
    write_depth_png(tmp / "first.png", depth[0])  # not named like a frame: used for frame 0
    out = tmp / "out"
    code = main(["--model", model, "--input", str(frames), "--output", str(out),
                 "--kind", "inverse", "--reference", str(tmp / "first.png"),
                 "--reference-fraction", "0.2", "--no-progress"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "scale-shift-inverse" in printed and "scale=0.5" in printed
    for i in range(N_FRAMES):
        got = read_depth_png(out / f"frame_{i:02d}.png")
        valid = depth[i] > 0
        rel = np.abs(got[valid] - depth[i][valid]) / depth[i][valid]
        assert np.median(rel) < 0.005
        assert (got[~valid] == 0).all()


@pytest.mark.parametrize("problem, message", [
    ("missing-model", "ONNX model not found"),
    ("empty-input", "no images"),
    ("unreadable", "cannot read image"),
    ("inverse-without-reference", "not metric depth; pass --reference"),
    ("bad-reference-size", "must have the same size"),
])
def test_clear_errors(scene, capsys, problem, message):
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, 2.0, 0.5), tmp / "inv.onnx")
    args = ["--model", model, "--input", str(frames), "--output", str(tmp / "out"),
            "--kind", "inverse", "--no-progress"]
    if problem == "missing-model":
        args[1] = str(tmp / "missing.onnx")
    elif problem == "empty-input":
        (tmp / "empty").mkdir()
        args[3] = str(tmp / "empty")
    elif problem == "unreadable":
        (frames / "frame_00.png").write_bytes(b"not a png")
        args += ["--reference", str(frames)]
    elif problem == "bad-reference-size":
        write_depth_png(tmp / "ref.png", np.ones((H + 1, W), np.float32))
        args += ["--reference", str(tmp / "ref.png")]
    assert main(args) == 2
    assert message in capsys.readouterr().err


def test_module_entry_point_reports_missing_model(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "depth", "--model", str(tmp_path / "none.onnx"),
         "--input", str(tmp_path), "--output", str(tmp_path / "out")],
        capture_output=True, text=True, timeout=120,
    )
    assert done.returncode == 2 and "ONNX model not found" in done.stderr
