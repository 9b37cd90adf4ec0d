export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD
timeout 150 python3 -m pytest -q -o addopts="" --import-mode=importlib -m "not slow" -n 4 -p no:cacheprovider -rf tests/vbgs/tracking tests/experiments/test_tracking_cli.py > /tmp/pytest.log 2>&1; echo "pytest rc=$?"; tail -4 /tmp/pytest.log
timeout 150 python3 -m experiments.run fit-scene --scene object --poses track --json 2>/dev/null | tail -1 > $OUT/track_object.json
python3 -c "import json; d=json.load(open('$OUT/track_object.json')); print({k: d.get(k) for k in ('psnr','ate_rmse','seconds_per_frame','tracking_seconds_per_frame')})"
