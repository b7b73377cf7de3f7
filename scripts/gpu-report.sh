#!/usr/bin/env bash
# Measurements on a machine with a GPU, results under $OUT (default ./gpu-report), most wanted
# first so that a lease cut short still brings them back: parity of the scorers and the
# simulators, the GPU-facing integration tests (where $IT names the test binary, `cargo test
# --release --test it --no-run`, run from the tree it was built in: it calls the binary by the
# path it was built at), a surface record's, the torsional strings' and the coupled bit's
# throughput, the evidence's and the demo's timing, the benchmark with the scoring shapes
# re-measured, the simulated maps on GPU and CPU (compared afterwards cell by cell), the rest of
# the integration tests, and the CPU's figures. Run from the project's root with the release
# binary built (`cargo build --release`); see docs/benchmarks.md for how it is run on a lent
# NVIDIA machine. Where $ARCHIVE names a file, the whole report is packed into it after every
# step: a lent machine returns only a few files, and a run cut short still returns the steps it
# finished (the archive outside $OUT or at its top). $EVIDENCE_RUNS sets how many times the
# evidence is timed (3).
set -u
OUT=${OUT:-gpu-report}
mkdir -p "$OUT"
B=${BITROCK:-target/release/bitrock}
export NODEVICE_SELECT=1 BITROCK_CACHE_DIR=${BITROCK_CACHE_DIR:-$(mktemp -d)}
PACKING=${ARCHIVE:+$(mktemp "$(dirname -- "$ARCHIVE")/.packing.XXXXXX")}
step() { # name timeout command...
    local name=$1 limit=$2; shift 2
    local t0=$(date +%s%N)
    timeout "$limit" "$@" >"$OUT/$name.out" 2>"$OUT/$name.err"
    local rc=$?
    echo "$name rc=$rc wall_ms=$(( ($(date +%s%N) - t0) / 1000000 ))" | tee -a "$OUT/steps.txt"
    # A failing step's last lines on standard output too, which a lent machine always returns.
    if [ "$rc" -ne 0 ]; then tail -n 40 "$OUT/$name.out" "$OUT/$name.err"; fi
    # A failing test run's panics too, which the harness prints above its last lines.
    if [ "$rc" -ne 0 ] && [[ $name == tests* ]]; then grep -A 6 '^---- ' "$OUT/$name.out" | head -n 150; fi
    # Packed under another name beside it, then renamed (a run cut while packing keeps the last
    # whole archive); where it lies in $OUT, neither name is packed, and tar's exit status 1 (a
    # file changed while read: the folder, as the packing is written into it) is no failure.
    if [ -n "${ARCHIVE:-}" ]; then
        tar czf "$PACKING" --warning=no-file-changed --exclude="./$(basename "$ARCHIVE")" \
            --exclude="./$(basename "$PACKING")" -C "$OUT" .
        if [ $? -le 1 ]; then chmod 644 "$PACKING" && mv "$PACKING" "$ARCHIVE"; fi
    fi
}
{ nproc; date -u; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>&1; } >"$OUT/machine.txt"
step devices 30 "$B" devices
step parity 90 "$B" parity
cat "$OUT/parity.out"
GPU_FACING=(gpu strings:: coupled:: tune:: uniform:: surface::)
if [ -n "${IT:-}" ]; then step tests 240 "$IT" --test-threads "$(nproc)" "${GPU_FACING[@]}"; fi
step surface_gpu 120 "$B" bench --surface --backend gpu --reps 3 --json
step strings_gpu 120 "$B" bench --strings --backend gpu --reps 3 --json
step coupled_gpu 120 "$B" bench --coupled --backend gpu --reps 3 --strings-n 100000 --json
for i in $(seq "${EVIDENCE_RUNS:-3}"); do step "evidence_gpu_$i" 60 "$B" evidence --backend gpu --start-from box; done
step demo 90 "$B" demo --out "$(mktemp -d)/demo"
step bench_retune 150 "$B" bench --retune --reps 3 --json
step coupled_map_gpu 60 "$B" coupled --map --wob-kn 150 --map-rpm 20:220:41 --map-wob-kn 60:300:25 --backend gpu --json
step map_100x100x200_gpu 120 "$B" stability --law m2 --params 13,6.5,0.3 --simulate --at-rpm 60 --at-kn 244.2 \
    --sim-omega-rpm 20:220:100 --sim-wob-kn 20:700:100 --sim-samples 200 --backend gpu --json
for b in gpu cpu; do
    step "sim_posterior_$b" 120 "$B" stability --run "${RUN_DIR:-tests/it/fixtures/runs/smc}" --simulate --at-rpm 60 --at-kn 244.2 \
        --sim-omega-rpm 20:220:21 --sim-wob-kn 20:700:18 --sim-samples 20 --backend "$b" --json
done
if [ -n "${IT:-}" ]; then
    step tests_rest 300 "$IT" --test-threads "$(nproc)" "${GPU_FACING[@]/#/--skip=}"
fi
step surface_cpu 120 "$B" bench --surface --backend cpu --reps 1 --json
step strings_cpu 120 "$B" bench --strings --backend cpu --reps 1 --strings-n 16384 --quick --json
step coupled_cpu 120 "$B" bench --coupled --backend cpu --reps 1 --strings-n 4096 --json
step watch 120 "$B" bench --watch --json
