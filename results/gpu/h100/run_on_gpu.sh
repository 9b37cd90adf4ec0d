#!/bin/bash
# GPU rows: answers at JAX's default precision (run side by side, so their seconds are not speed figures),
# the library's tracking/inference tests on the GPU, then bench stream alone (its seconds are the speed figures).
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD
nvidia-smi -L; git log --oneline -1 2>/dev/null
python3 -c "import jax; print('jax', jax.__version__, jax.devices())" 2>&1 | tail -1
ans() { name=$1; t=$2; shift 2; s=$(date +%s); timeout $t python3 -m experiments.run "$@" > /tmp/$name.out 2> /tmp/$name.err; rc=$?; e=$(date +%s); echo "== $name rc=$rc wall=$((e - s)) s $*"; tail -1 /tmp/$name.out > $OUT/$name.json; tail -3 /tmp/$name.err | cut -c1-300; }
ans fit_image 150 fit-image --json &
ans fit_scene_object 200 fit-scene --scene object --json &
ans fit_scene_room 220 fit-scene --scene room --json &
ans fit_scene_walk 220 fit-scene --scene walk --json &
ans track_object 220 fit-scene --scene object --poses track --json &
timeout 220 python3 -m pytest -q -o addopts="" --import-mode=importlib -m "not slow" -n 4 --dist loadfile -p no:cacheprovider -rf tests/vbgs/tracking tests/vbgs/inference > /tmp/pytest.log 2>&1; echo "pytest rc=$?"; tail -12 /tmp/pytest.log
wait
s=$(date +%s); timeout 200 python3 -m experiments.run bench stream --sizes 128 640x480 --out /tmp/bench > /tmp/bench.out 2>/tmp/bench.err; echo "== bench rc=$? wall=$(( $(date +%s) - s )) s"
tail -45 /tmp/bench.out; tail -3 /tmp/bench.err
cp /tmp/bench/bench_stream_gpu.md $OUT/ 2>/dev/null; cp /tmp/bench/bench_stream_gpu_profile.md $OUT/ 2>/dev/null
ls /tmp/bench
