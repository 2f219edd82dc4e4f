#!/usr/bin/env bash
# GPU measurements of issue #16 item 4 on a lent device machine (docs/benchmarks.md, "GPU").
#
#   bash benchmarks/gpu_session.sh bench              # build, smoke run, throughput A/B pairs
#   bash benchmarks/gpu_session.sh bench2             # build, more A/B pairs (bf16, page-locking)
#   bash benchmarks/gpu_session.sh train SPEC...      # build, then training runs side by side
#   DEADLINE=<epoch s> bash benchmarks/gpu_session.sh all SPEC...   # both; SPEC limits "auto"
#   bash benchmarks/gpu_session.sh long SPEC          # build, one run, continued across calls
#
# SPEC is NAME:ENV_THREADS:SECONDS:OVERRIDES (overrides separated by commas); SECONDS "auto"
# runs until 20 s before $DEADLINE. Each run's learning curve (benchmarks/learning_curve.py)
# is printed at the end.
#
# `long` trains one run longer than a device call (or a session's device budget) allows. It
# starts the run, or resumes it (`resume=`) when the call carried its folder in .gpu_runs/NAME
# (ignored by git), and returns the folder with its newest checkpoint as $OUT/NAME_run.tgz:
#   tar xzf <files_at>/NAME_run.tgz -C .gpu_runs     # here, then the next call (or session)
#   run carry=[".whl", ".maps", ".gpu_runs"]  bash benchmarks/gpu_session.sh long SPEC
# with the same SPEC each time (the env and model must match the checkpoint; `total_steps` sets
# the learning-rate schedule, so fix it in the first call). Give the run
# `trainer.checkpoint_interval` of about a minute of updates: a killed call loses what came
# after its last checkpoint. learning_curve.py leaves the pauses between calls out of its minutes.
#
# Sizing (session 10, H100 + 16-core Xeon): the build takes 35-47 s; a paper-size bench worker
# needs ~40 s to start and warm up and ~14 s per update, so `bench` needs about 10 minutes,
# a whole device call. With a 15-minute device budget run `bench` in one call and `train` in
# another, not `all`.
#
# The device machine is bare: its python3 holds torch (CUDA) but not hydra-core, omegaconf,
# antlr4, gymnasium or shapely. Their wheels (cp312, manylinux) travel in .whl/ (ignored by git),
# the Tartu map in .maps/tartu_lanelet2/ (ignored; never committed). Every step has its own
# time limit and writes its log under $W; after each step everything but checkpoints is packed
# into $OUT/results.tgz (the device tool returns at most 8 files), so a failed or killed step
# costs only its own minutes.
set -u
OUT=${OUT:-/tmp/gpu_out}
W=${GPU_WORK:-/tmp/gpu_work}
mkdir -p "$OUT" "$W"
pack() { tar czf "$OUT/results.tgz" --exclude='*.pt' -C "$W" . 2>/dev/null; }
part=${1:-bench}
shift || true

python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl >"$W/pip.log" 2>&1 || { cat "$W/pip.log"; exit 1; }
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 SELFPLAYDRIVE_SHARED_MAPS=$PWD/.maps
export PYTORCH_CUDA_ALLOC_CONF=expandable_segments:True
t0=$(date +%s)
python3 setup.py build_ext --inplace -j "$(nproc)" >"$W/build.log" 2>&1 || { tail -40 "$W/build.log"; exit 1; }
echo "build: $(($(date +%s) - t0)) s"
nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm --format=csv | tee "$W/gpu.txt"
python3 -c "import torch, numpy; print('torch', torch.__version__, 'cuda', torch.version.cuda, 'numpy', numpy.__version__, 'cpus', __import__('os').cpu_count())" | tee -a "$W/gpu.txt"
lscpu | grep -E "Model name|^CPU\(s\)" | tee -a "$W/gpu.txt"

step() {  # step NAME SECONDS CMD...: run CMD with a limit, log to $OUT/NAME.log, print its tail
    local name=$1 limit=$2
    shift 2
    local s=$(date +%s)
    timeout -k 5 "$limit" "$@" >"$W/$name.log" 2>&1
    local rc=$?
    echo "== $name: rc $rc, $(($(date +%s) - s)) s"
    tail -n 4 "$W/$name.log"
    pack
}

bench() {  # bench NAME SECONDS OVERRIDES... -- BASELINE-OVERRIDES...
    local name=$1 limit=$2
    shift 2
    step "$name" "$limit" python3 benchmarks/bench_train.py --json-out "$W/$name.json" "$@"
}

if [ "$part" = bench ] || [ "$part" = all ]; then
    step smoke 60 python3 -m selfplaydrive.cli train trainer.device=cuda env.num_worlds=4 \
        trainer.total_steps=8192 trainer.eval_episodes=2 logger=jsonl hydra.run.dir="$W/smoke_run"
    # the Transformer at its paper world count (128 x 32 = 4,096 slots), bf16 vs fp32
    bench tf_bf16_fp32 170 experiment=paper_transformer map=tartu --updates 2 \
        --baseline-overrides trainer.precision=fp32
    # paper Deep Sets (512 x 32 = 16,384 slots, bf16): the next rollout collected during the
    # update's last epoch (overlap_collection) vs collection after the update
    bench ds_overlap 230 experiment=paper_deepsets map=tartu --updates 3 trainer.overlap_collection=true \
        --baseline-overrides trainer.overlap_collection=false
fi
if [ "$part" = bench2 ]; then  # the comparisons of session 10's `bench`
    bench ds_bf16_fp32 200 experiment=paper_deepsets map=tartu --updates 3 \
        --baseline-overrides trainer.precision=fp32
    bench ds_register 150 experiment=paper_deepsets map=tartu --updates 2 \
        --baseline-overrides trainer.host_register=false
fi
if [ "$part" = long ]; then
    IFS=: read -r name threads limit ovr <<<"${1:?long needs one SPEC}"
    # the same absolute folder on every machine, so that the checkpoint's records stay true
    start=("hydra.run.dir=$W/$name")
    if [ -d ".gpu_runs/$name" ]; then  # continue it there; this call's Hydra folder gets resume.json
        rm -rf "${W:?}/$name" && cp -r ".gpu_runs/$name" "$W/$name" &&
            start=("resume=$W/$name" "hydra.run.dir=$W/${name}_call$(date +%s)")
    fi
    echo "== long $name: $limit s, ${start[*]}, $ovr"
    timeout -k 5 "$limit" python3 -m selfplaydrive.cli train logger=jsonl trainer.device=cuda \
        trainer.progress_bar=false env.num_threads="$threads" "${start[@]}" ${ovr//,/ } >>"$W/$name.log" 2>&1
    echo "== long $name: rc $?"
    tail -n 4 "$W/$name.log"
    python3 benchmarks/learning_curve.py "$W/$name/metrics.jsonl" | tee "$W/$name.curve.txt"
    pack
    tar czf "$OUT/${name}_run.tgz" -C "$W" "$name"
fi
if [ "$part" = train ] || [ "$part" = all ]; then
    for spec in "$@"; do
        IFS=: read -r name threads limit ovr <<<"$spec"
        [ "$limit" = auto ] && limit=$((${DEADLINE:?DEADLINE is needed for auto} - $(date +%s) - 20))
        echo "== train $name: $limit s, $ovr"
        timeout -k 5 "$limit" python3 -m selfplaydrive.cli train logger=jsonl trainer.device=cuda \
            trainer.progress_bar=false env.num_threads="$threads" hydra.run.dir="$W/$name" \
            ${ovr//,/ } >"$W/$name.log" 2>&1 &
    done
    while [ -n "$(jobs -r)" ]; do sleep 10; pack; done
    for spec in "$@"; do
        name=${spec%%:*}
        python3 benchmarks/learning_curve.py "$W/$name/metrics.jsonl" | tee "$W/$name.curve.txt" ||
            tail -5 "$W/$name.log"
    done
    pack
fi
