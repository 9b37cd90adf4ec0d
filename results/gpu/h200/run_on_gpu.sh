#!/bin/bash
# GPU rows on the lent machine: the answers at JAX's default precision side by side (their
# seconds are not speed figures), then alone (speed figures): the room at 640x480 under the
# Kinect with each candidate search, the walk at 640x480, and bench stream.
export PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD
nvidia-smi -L
python3 -c "import jax; print('jax', jax.__version__, jax.devices())" 2>&1 | tail -1
ans() { name=$1; t=$2; shift 2; s=$(date +%s); timeout $t python3 -m experiments.run "$@" > /tmp/$name.out 2> /tmp/$name.err; rc=$?; e=$(date +%s); echo "== $name rc=$rc wall=$((e - s)) s $*"; tail -1 /tmp/$name.out > $OUT/$name.json; tail -2 /tmp/$name.err | cut -c1-300; }
ans fit_image 150 fit-image --json &
ans fit_scene_object 170 fit-scene --scene object --json &
ans fit_scene_room 170 fit-scene --scene room --json &
ans fit_scene_walk 170 fit-scene --scene walk --json &
wait
ans room640_kinect_projective 110 fit-scene --scene room --size 640x480 --frames 20 --components 100000 --simulate-sensor kinect --sensor kinect --search projective --stage-times --test-views 2 --json
ans room640_kinect_kdtree 110 fit-scene --scene room --size 640x480 --frames 20 --components 100000 --simulate-sensor kinect --sensor kinect --search kdtree --stage-times --test-views 2 --json
ans walk640_projective 110 fit-scene --scene walk --size 640x480 --frames 20 --components 100000 --search projective --stage-times --test-views 2 --json
s=$(date +%s); timeout 120 python3 -m experiments.run bench stream --sizes 128 640x480 --out /tmp/bench > /tmp/bench.out 2>/tmp/bench.err; echo "== bench rc=$? wall=$(( $(date +%s) - s )) s"
tail -3 /tmp/bench.err; cp /tmp/bench/bench_stream_gpu.md /tmp/bench/bench_stream_gpu_profile.md $OUT/ 2>/dev/null
for f in $OUT/*.json; do python3 -c "import json; d=json.load(open('$f')); print('$f', {k: d.get(k) for k in ('psnr','seconds_per_frame','stage_seconds')})" 2>/dev/null; done
cd $OUT && tar czf rows.tgz *.json *.md 2>/dev/null && rm -f *.json *.md; ls $OUT
