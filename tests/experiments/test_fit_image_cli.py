"""End to end: ``python -m experiments.run fit-image`` and ``bench image``."""

import json
import subprocess
import sys

from experiments.run import main


def _run(*args):
    return subprocess.run([sys.executable, "-m", "experiments.run", *args],
                          capture_output=True, text=True, timeout=600)


def test_fit_image_json_and_png(tmp_path):
    png = tmp_path / "cmp.png"
    out = _run("fit-image", "--image", "coffee", "--size", "32", "--components", "300",
               "--iters", "4", "--save", str(png), "--json")
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    for key in ("psnr", "ssim", "seconds", "components_used", "elbo"):
        assert key in result
    assert result["command"] == ("python -m experiments.run fit-image --image coffee --size 32 "
                                 f"--components 300 --iters 4 --save {png} --json")
    assert result["code_version"]  # the commit, +dirty, or unknown
    # measured 31.03 dB, SSIM 0.955
    assert result["psnr"] > 30.1 and 0.9 < result["ssim"] <= 1
    assert len(result["elbo"]) == 4 and result["elbo"][-1] >= result["elbo"][0]
    assert png.stat().st_size > 10_000


def test_fit_image_patch_stream_summary_and_scores(capsys):
    args = ["fit-image", "--image", "chelsea", "--size", "24", "--components", "200",
            "--stream", "patches", "--order", "reversed", "--assign", "posterior"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "psnr" in out and "components_used" in out
    assert main([*args, "--json"]) == 0
    result = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    # measured 31.37 dB, SSIM 0.942 after one pass over the 9 patches
    assert result["psnr"] > 30.4 and result["ssim"] > 0.9


def test_fit_image_loads_and_resizes_the_image_once(monkeypatch, capsys, tmp_path):
    import experiments.tasks.image_task as image_task
    import vbgs.data.images as images
    from vbgs.compilation import cache_dir

    if cache_dir() is not None:  # JAX's cache where it was; the photos under tmp_path
        monkeypatch.setenv("VBGS_COMPILE_CACHE", str(cache_dir()))
    # VBGS_CACHE_DIR (the session's temporary cache, tests/conftest.py) wins over
    # XDG_CACHE_HOME: both are pointed here
    monkeypatch.setenv("VBGS_CACHE_DIR", str(tmp_path / "vbgs"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))

    calls = []

    def counted(*args, **kwargs):
        calls.append(args)
        return load(*args, **kwargs)

    load = images.load_image
    monkeypatch.setattr(images, "load_image", counted)
    monkeypatch.setattr(image_task, "load_image", counted)
    # test_fit_image_json_and_png's fit: its executables are in the session's compile
    # cache (tests/conftest.py), written by that test's process
    assert main(["fit-image", "--image", "coffee", "--size", "32", "--components", "300",
                 "--iters", "4", "--json"]) == 0
    assert calls == [("coffee", 32)]
    if cache_dir() is not None:  # kept resized for the next run
        assert [p.name[:12] for p in (tmp_path / "vbgs" / "images").iterdir()] == ["coffee-32x32"]
    assert json.loads(capsys.readouterr().out.strip().splitlines()[-1])["height"] == 32


def test_fit_image_bad_input_is_one_clear_line(capsys):
    """One refusal through a real process (exit status 2, the reason, no traceback: what a
    shell sees); the others in-process through the same entry point (a process start
    and JAX import each, ~4 s, for the same path)."""
    out = _run("fit-image", "--size", "8", "--image", "/no/such/file.png")
    assert out.returncode == 2
    assert "neither a bundled photo" in out.stderr and "Traceback" not in out.stderr
    for args, message in ((["--components", "0"], "components must be a positive integer"),
                          (["--iters", "0"], "iters must be a positive integer")):
        assert main(["fit-image", "--size", "8", *args]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err


def test_bench_image_writes_tables(tmp_path):
    assert main(["bench", "image", "--sizes", "16", "--components", "20", "40",
                 "--iters", "1", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "bench_image.md").read_text()
    assert "Measured on:" in text and "seconds_per_iter" in text
    assert (f"Command: `python -m experiments.run bench image --sizes 16 --components 20 40 "
            f"--iters 1 --out {tmp_path}`") in text
    assert len((tmp_path / "bench_image.csv").read_text().splitlines()) == 3
