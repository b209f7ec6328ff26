#!/usr/bin/env bash
# The GPU path on a device machine (run through the device tool from the repository root). That
# machine reaches no package index and has no Rust toolchain, so what it runs is built here:
#   - the extension, python/physcore/_core.abi3.so (`maturin develop --release`), carried;
#   - the Rust GPU tests' binaries, copied stripped into .devbin/ (see below), carried;
#   - the Vulkan loader's .deb files in .gl/ (the device README), carried;
#   - ../shared/gpu/cuda_reference.py copied into .devbin/ (the CUDA peer on the same card).
# It runs the GPU tests (Rust and Python) on the real adapter, then the N-body, grid (Gray-Scott,
# wave, the stable fluid) and cloth benches beside the CUDA reference (and benches/gpu/cuda_wave.py, the wave's CUDA
# peer) in the same call, so every ratio is of one card, and the galaxies scene's energy drift at
# 10^5 stars in f32 and f64. Each part has its own time limit so that one stuck part cannot eat
# the call. Everything it prints goes to $OUT/device_check.txt too. Budget: about 4 minutes (plus
# the machine's start);
# `--no-cuda` skips the CUDA reference (the half minute it takes). With
# .devbin/base_core.abi3.so(.gz) carried (a baseline build), the Gray–Scott bench also runs
# alternately with it and with this tree's extension (A/B on one card, one call); so does the wave.
#
# Here, before the call (the tree that travels is at most 64 MiB: binaries stripped and gzipped):
#   CARGO_TARGET_DIR=/work/tgt-gpu cargo test --release -p physcore-core --lib --no-run
#   CARGO_TARGET_DIR=/work/tgt-gpu cargo test --release -p physcore-gpu --tests --no-run
#   mkdir -p .devbin; cp the binaries to .devbin/{physcore_core-lib,physcore_gpu-tests,particles-tests,
#   gray_scott-tests,cells-tests,sph-tests,sph_bench-tests,dem-tests,dfsph-tests} and python/physcore/_core.abi3.so to .devbin/; strip and gzip -9 them;
#   cp ../shared/gpu/cuda_reference.py .devbin/
# then run(command="bash benches/gpu/device_check.sh", carry=[".gl", ".devbin"]).
set -uo pipefail
out="${OUT:-/tmp}/device_check.txt"
exec > >(tee "$out") 2>&1
. benches/gpu/device_env.sh
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv 2>/dev/null || true
lscpu | grep -E "Model name|^CPU\(s\)" || true
python3 -c 'import physcore as pc; print(pc.__version__, pc.simd_level()); [print(a) for a in pc.gpu_adapters()]' || exit 1
section() { echo; echo "=== $1 ($SECONDS s)"; }
part_tests() {
section "Rust GPU tests"
for b in .devbin/physcore_gpu-tests .devbin/particles-tests .devbin/gray_scott-tests .devbin/cells-tests .devbin/sph-tests .devbin/dem-tests .devbin/dfsph-tests; do
  [ -x "$b" ] && timeout 120 "$b" --test-threads 4 2>&1 | tail -4
done
[ -x .devbin/physcore_core-lib ] && timeout 120 .devbin/physcore_core-lib device --test-threads 4 2>&1 | tail -4
}
part_sph() {
section "WCSPH on the device (2D 4M, 3D 1M, f32; then f64)"
if [ -x .devbin/sph_bench-tests ]; then
  timeout 90 .devbin/sph_bench-tests --ignored --nocapture 2>&1 | grep -E "adapter|WCSPH"
  PHYSCORE_SPH_PRECISION=f64 PHYSCORE_SPH_BENCH=2d:1048576,3d:262144 timeout 60 .devbin/sph_bench-tests --ignored --nocapture 2>&1 | grep -E "WCSPH"
fi
}
part_dem() {
section "DEM on the device (bare steps: 10^4, 10^5, 10^6 discs, f32 and f64)"
[ -x .devbin/dem-tests ] && timeout 90 .devbin/dem-tests --ignored --nocapture bench 2>&1 | grep -E "adapter|discs|DEM"
}
part_dfsph() {
section "DFSPH on the device (bare steps of the 3D dam break, f32)"
[ -x .devbin/dfsph-tests ] && timeout 90 .devbin/dfsph-tests --ignored --nocapture bench 2>&1 | grep -E "adapter|DFSPH|panicked"
}
part_ab_rust() {
section "A/B: the bare WCSPH (4M 2D, 1M 3D), DFSPH (3D, 262,144 and 1M) and DEM benches, base binaries then this tree's (WCSPH and DFSPH 2 rounds)"
if [ -x .devbin/base_sph_bench-tests ]; then
  for r in 1 2; do
    for who in base this; do
      b=.devbin/sph_bench-tests; [ $who = base ] && b=.devbin/base_sph_bench-tests
      timeout 60 $b --ignored --nocapture wcsph_throughput 2>&1 | grep -E "^WCSPH" | sed "s/^/$r $who  /"
    done
  done
fi
if [ -x .devbin/base_dfsph-tests ]; then
  for r in 1 2; do
    for who in base this; do
      b=.devbin/dfsph-tests; [ $who = base ] && b=.devbin/base_dfsph-tests
      # h = 1.0 dx, 3D's default since 2026-12-01 (a base built before then ignores the variable
      # and runs 1.3), then 1.3 dx, the default before.
      for hs in 1.0 1.3; do
        PHYSCORE_DFSPH_SMOOTHING=$hs PHYSCORE_DFSPH_BENCH=262144,1048576 timeout 60 $b --ignored --nocapture bench_dam_break_3d 2>&1 | grep -E "^DFSPH" | sed "s/^/$r $who h=$hs  /"
      done
    done
  done
fi
if [ -x .devbin/base_dem-tests ]; then
  for who in base this; do
    b=.devbin/dem-tests; [ $who = base ] && b=.devbin/base_dem-tests
    timeout 60 $b --ignored --nocapture bench_discs 2>&1 | grep -E "discs F32" | sed "s/^/$who  /"
  done
fi
}
part_pytests() {
section "Python GPU tests"
timeout 200 python3 -m pytest -p no:cacheprovider -p no:benchmark -o addopts="" -q -n 8 tests/gpu 2>&1 | tail -15
}
part_auto() {
section "device='auto'"
python3 - <<'PY'
import numpy as np, physcore as pc
for n in (256, 4096, 65536):
    s = pc.Scene(dim=3, integrator="verlet", dt=1e-4, device="auto")
    s.add_particles(np.random.default_rng(0).normal(size=(n, 3)), masses=1.0 / n)
    s.add(pc.PairwiseGravity(G=1.0, softening=0.05))
    s.step(2)
    print(n, s.device, s.precision, "|", s.device_reason)
PY
}
part_nbody() {
section "N-body (CPU to 65536)"
timeout 150 python3 benches/gpu/bench_gpu_nbody.py --device gpu --n 1024,4096,16384,65536,262144 --steps 10 --cpu-max 65536
timeout 60 python3 benches/gpu/bench_gpu_nbody.py --device gpu --n 1048576 --steps 2 --cpu-max 0 | tail -3
}
part_batch() {
section "Batches of three-body problems (CPU to 16384 worlds)"
timeout 120 python3 benches/gpu/bench_gpu_batch.py --device gpu --m 1024,16384,65536 --steps 1000 --cpu-max 16384
}
part_grids() {
section "Grids: Gray-Scott and the wave"
timeout 150 python3 benches/gpu/bench_gpu_grids.py --device gpu --n 128,512,1024,4096 --steps 100
}
part_sph_scene() {
section "WCSPH dam break, scene level (2D to 10^6, 3D to 10^6; CPU to 41k)"
timeout 150 python3 benches/gpu/bench_gpu_sph.py --device gpu --n 72,144,720 --steps 20 --cpu-max 144
timeout 150 python3 benches/gpu/bench_gpu_sph.py --device gpu --dim 3 --n 24,48,80 --steps 10 --cpu-max 24
}
part_dfsph_scene() {
section "DFSPH dam break, scene level (2D to 10^6, 3D to 10^6; CPU to 41k)"
timeout 120 python3 benches/gpu/bench_gpu_sph.py --method dfsph --device gpu --n 72,144,720 --steps 10 --cpu-max 144
timeout 120 python3 benches/gpu/bench_gpu_sph.py --method dfsph --device gpu --dim 3 --n 24,48,80 --steps 5 --cpu-max 24
}
part_dam_gif() {
section "The 10^6-particle 3D dam break GIF on the GPU (DFSPH, n=80: 1,024,000 water particles; target <= 60 s)"
t0=$(date +%s.%N)
timeout 150 python3 -m physcore render dam_break --param dim=3 --param n=80 --param device=gpu -o "${OUT:-/tmp}/dam_break_3d_gpu.gif" 2>&1 | tr '\r' '\n' | grep -v "^ *$" > /tmp/gif.log
awk 'NR % 25 == 1' /tmp/gif.log; tail -4 /tmp/gif.log
python3 -c "import time; print('wall', round(time.time() - $t0, 2), 's')"
}
part_liquid_draw() {
section "Drawing a 10^6-particle liquid's GIF on the host's cores (1 drawing thread, then the default; same bytes)"
timeout 150 python3 benches/render/bench_liquid_draw.py --rounds 1
}
part_fluid() {
section "The stable fluid (CPU to 1024²)"
timeout 150 python3 benches/gpu/bench_gpu_grids.py --device gpu --kinds fluid --n 256,1024,4096 --steps 20 --cpu-max 1024
}
part_ab() {
section "A/B: Gray-Scott and the wave at 1024² and 4096² (base, then this tree; 3 rounds)"
if [ -f .devbin/base_core.abi3.so ]; then
  # A/B in one call: the same benches alternately with a baseline build of the extension
  # (carried as .devbin/base_core.abi3.so; the Python package is this tree's) and this one.
  mkdir -p /tmp/base && cp -r python/physcore /tmp/base/ && cp .devbin/base_core.abi3.so /tmp/base/physcore/_core.abi3.so
  for r in 1 2 3; do
    for who in base this; do
      pp=""; [ $who = base ] && pp=/tmp/base
      PYTHONPATH=${pp:-$PWD/python} timeout 60 python3 benches/gpu/bench_gpu_grids.py --device gpu --n 1024,4096 --steps 300 --cpu-max 0 2>&1 | grep -F "²" | sed "s/^/$r $who  /"
    done
  done
fi
}
part_galaxies() {
section "galaxies at 10^5 stars: energy drift over the render's 952 steps, f32 and f64"
timeout 90 python3 - <<'PY'
import time, physcore as pc
g = pc.scenes.galaxies(n=100_000)
for prec in ("f32", "f64"):
    s = pc.Scene(dim=3, integrator="verlet", dt=g.dt, device="gpu", precision=prec)
    s.add_particles(g.positions, velocities=g.velocities, masses=g.masses)
    s.add(pc.PairwiseGravity(G=1.0, softening=0.05))
    e0 = s.energy().total
    t = time.perf_counter()
    drift = []
    for _ in range(8):
        s.step(119)
        drift.append((s.energy().total - e0) / abs(e0))
    print(prec, f"{time.perf_counter() - t:.2f} s;", "drift every 119 steps:", " ".join(f"{d:+.2e}" for d in drift), flush=True)
PY
}
part_cloth() {
section "cloth"
timeout 90 python3 benches/gpu/bench_gpu_cloth.py --device gpu --n 16,64,256,1024 --steps 50
}
part_cuda() {
section "CUDA reference (CuPy)"
[ "${1:-}" != "--no-cuda" ] && [ -f .devbin/cuda_reference.py ] && timeout 90 python3 .devbin/cuda_reference.py --no-numba --nbody-n 65536,262144 --grid 4096 2>&1 | tail -12
[ "${1:-}" != "--no-cuda" ] && timeout 60 python3 benches/gpu/cuda_wave.py --n 1024,4096 --steps 300
}
part_galaxies_gif() {
section "galaxies rendered on the GPU at its default size (10^5 stars)"
t0=$(date +%s.%N)
timeout 100 python3 -m physcore render galaxies --param device=gpu -o "${OUT:-/tmp}/galaxies_gpu.gif" -q
python3 -c "import time; print('wall', round(time.time() - $t0, 2), 's')"
}
# PARTS (a comma list, e.g. PARTS=sph,dem,batch) picks the parts and their order; all of
# them, in the order above, by default.
for part in $(echo "${PARTS:-tests,sph,dem,dfsph,pytests,auto,nbody,batch,grids,sph_scene,dfsph_scene,dam_gif,fluid,ab,galaxies,cloth,cuda,galaxies_gif,ab_rust}" | tr , ' '); do
  if declare -F "part_$part" >/dev/null; then "part_$part" "$@"; else echo "no part named $part"; fi
done
section "done"
