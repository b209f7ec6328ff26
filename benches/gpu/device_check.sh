#!/usr/bin/env bash
# The GPU path on a device machine (run through the device tool from the repository root):
# builds the wheel, runs the GPU tests (Rust and Python) on the real adapter, then the N-body
# and Gray-Scott benches beside ../shared/gpu/cuda_reference.py in the same call, so the ratio is of one card.
# Everything it prints goes to $OUT/device_check.txt too. Budget: about 6 minutes on 16 cores.
set -uo pipefail
out="${OUT:-/tmp}/device_check.txt"
exec > >(tee "$out") 2>&1
nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>/dev/null || true
python3 -m venv /tmp/pcv && . /tmp/pcv/bin/activate
pip install -q maturin numpy pillow tqdm pytest hypothesis >/dev/null 2>&1
CARGO_PROFILE_RELEASE_LTO=false CARGO_PROFILE_RELEASE_CODEGEN_UNITS=16 pip install -q . || exit 1
python3 -c 'import physcore as pc; [print(a) for a in pc.gpu_adapters()]'
PHYSCORE_GPU_REQUIRED=1 cargo test --release -p physcore-gpu 2>&1 | tail -5
PHYSCORE_GPU_REQUIRED=1 python3 -m pytest -p no:cacheprovider -n 0 -q tests/gpu 2>&1 | tail -5
python3 benches/gpu/bench_gpu_nbody.py --device gpu --n 65536,262144 --steps 10
python3 benches/gpu/bench_gpu_grids.py --device gpu --n 1024,4096 --steps 100
if [ -f shared/gpu/cuda_reference.py ]; then
  python3 shared/gpu/cuda_reference.py --no-numba --nbody-n 65536,262144 --grid 4096 2>&1 | tail -20
fi
