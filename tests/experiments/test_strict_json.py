"""Every command's JSON is strict: non-finite numbers are null with a reason beside them."""

import json

import numpy as np
from PIL import Image

from experiments.run import main
from experiments.cli.output import dumps, sanitise


def strict(line: str) -> dict:
    def refuse(name):
        raise ValueError(f"{name} is not JSON")
    return json.loads(line, parse_constant=refuse)


def test_non_finite_numbers_become_null_with_a_reason():
    record = {"psnr": float("inf"), "ssim": np.float32(1.0), "residual": float("nan"),
              "rows": [{"seconds": float("nan"), "psnr": 20.0}], "curve": [1.0, np.nan]}
    out = strict(dumps(record))
    assert out["psnr"] is None and "zero error" in out["psnr_note"]
    assert out["residual"] is None and "NaN" in out["residual_note"]
    assert out["rows"][0]["seconds"] is None and out["rows"][0]["seconds_note"]
    assert out["curve"] == [1.0, None] and out["curve_note"].startswith("entries 1 are null")
    assert out["ssim"] == 1.0 and sanitise({"a": 1})["a"] == 1


def test_a_black_image_fits_to_strict_json(tmp_path, capsys):
    """A black image is fitted exactly: its PSNR is +inf, printed as null with the reason."""
    path = tmp_path / "black.png"
    Image.fromarray(np.zeros((16, 16, 3), np.uint8)).save(path)
    code = main(["fit-image", "--image", str(path), "--size", "16", "--components", "20",
                 "--iters", "2", "--json"])
    out = capsys.readouterr().out.strip().splitlines()[-1]
    assert code == 0
    record = strict(out)
    assert record["psnr"] is None and "zero error" in record["psnr_note"]
