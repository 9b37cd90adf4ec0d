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
    ("unreadable", "could not read image file"),
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


# bad input never gives a silently wrong number ------------------------------------------


def _args(model, frames, out, *extra):
    return ["--model", model, "--input", str(frames), "--output", str(out), "--kind", "metric",
            "--no-progress", *extra]


def test_negative_depth_model_is_refused_before_writing(scene, capsys):
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, -1.0, 0.0, space="depth"), tmp / "neg.onnx")
    out = tmp / "out"
    assert main(_args(model, frames, out)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert (f"frame_00.png: no pixel has valid depth (0 of {H * W} kept" in err
            and "nothing was written" in err and "output spans -3.9" in err)
    assert not out.exists()  # not even the folder


def test_mostly_invalid_frames_are_warned_with_pixel_counts(scene, capsys):
    tmp, frames, rgb, depth = scene
    depth = depth.copy()
    depth[1] = 0.0  # the model gives no depth for frame 1
    depth[2, : H // 2 + 2] = 0.0  # and for just over half of frame 2
    model = _save(depth_lookup_model(rgb, depth, 1.0, 0.0, space="depth"), tmp / "m.onnx")
    assert main(_args(model, frames, tmp / "out")) == 0
    captured = capsys.readouterr()
    kept = int((depth > 0).sum())
    assert f"valid depth: {kept} of {N_FRAMES * H * W} pixels kept" in captured.out
    assert (f"warning: 2 of 3 frames kept valid depth at under 50% of their pixels "
            f"(worst frame_01.png: 0 of {H * W})") in captured.err
    assert (read_depth_png(tmp / "out" / "frame_01.png") == 0).all()


def test_output_that_is_a_file_is_refused_before_work(scene, capsys):
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, 1.0, 0.0, space="depth"), tmp / "m.onnx")
    existing = tmp / "depth.txt"
    existing.write_text("keep me")
    assert main(_args(model, frames, existing)) == 2
    assert f"--output {existing} is a file, not a folder" in capsys.readouterr().err
    assert existing.read_text() == "keep me"


def test_ctrl_c_leaves_only_complete_pngs_and_one_line(scene, capsys, monkeypatch):
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, 1.0, 0.0, space="depth"), tmp / "m.onnx")
    import vbgs.data.depth_png as depth_png

    real_imsave, calls = depth_png.skio.imsave, []

    def imsave_then_interrupt(path, *a, **k):  # Ctrl-C halfway through the second file
        calls.append(path)
        if len(calls) == 2:
            path.write_bytes(b"\x89PNG\r\n\x1a\n truncated")
            raise KeyboardInterrupt
        return real_imsave(path, *a, **k)

    monkeypatch.setattr(depth_png.skio, "imsave", imsave_then_interrupt)
    out = tmp / "out"
    assert main(_args(model, frames, out)) == 130
    err = capsys.readouterr().err
    assert err == f"interrupted: 1 of 3 depth PNGs written to {out}, each complete\n"
    assert sorted(p.name for p in out.iterdir()) == ["frame_00.png"]
    np.testing.assert_array_equal(read_depth_png(out / "frame_00.png"),
                                  np.round(depth[0] * MM) / MM)


def test_8bit_reference_depth_is_refused_naming_the_file(scene, capsys):
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, 2.0, 0.5), tmp / "inv.onnx")
    ref = tmp / "ref8.png"
    skio.imsave(ref, np.full((H, W), 200, np.uint8), check_contrast=False)
    assert main(["--model", model, "--input", str(frames), "--output", str(tmp / "out"),
                 "--kind", "inverse", "--reference", str(ref), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"error: reference depth: {ref}: depth PNGs must be 16-bit" in err and "8-bit" in err


@pytest.mark.parametrize("inside", [False, True])
def test_output_in_the_input_folder_is_refused_and_nothing_is_written(scene, capsys, inside):
    """--output equal to --input would overwrite the RGB frames with depth PNGs of the
    same names (data loss, exit 0 before); inside it, they would mix with the frames."""
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, 1.0, 0.0, space="depth"), tmp / "m.onnx")
    before = {p.name: p.read_bytes() for p in frames.iterdir()}
    out = frames / "depth" if inside else frames
    assert main(["--model", model, "--input", str(frames), "--output", str(out),
                 "--kind", "metric", "--no-progress"]) == 2
    assert "--input folder" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in frames.iterdir()} == before


@pytest.mark.parametrize("extra, words", [
    (["--depth-scale", "0"], "--depth-scale must be a finite number > 0"),
    (["--reference-scale", "0"], "--reference-scale must be a finite number > 0"),
    (["--input-size", "-1"], "--input-size must be at least 8 pixels"),
    (["--input-size", "0"], "--input-size must be at least 8 pixels"),
    (["--input-size", "1"], "gives one depth for the whole frame"),
], ids=["depth scale 0", "reference scale 0", "input -1", "input 0", "input 1"])
def test_numbers_that_cannot_work_are_refused_before_any_frame(scene, capsys, extra, words):
    tmp, frames, rgb, depth = scene
    model = _save(depth_lookup_model(rgb, depth, 1.0, 0.0, space="depth"), tmp / "m.onnx")
    out = tmp / "out"
    code = main(["--model", model, "--input", str(frames), "--output", str(out),
                 "--kind", "metric", "--no-progress", *extra])
    err = capsys.readouterr().err
    assert code == 2 and words in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()
