#!/usr/bin/env bash
# A short device call for one change: the GPU tests on the real adapter, then the cloth and grid
# benches alternately with a baseline build of the extension (.devbin/base_core.abi3.so) and this
# tree's (.devbin/_core.abi3.so), 3 rounds, the device's times only (no CPU runs). Built and
# carried as for device_check.sh; run(command="bash benches/gpu/device_ab.sh",
# carry=[".gl", ".devbin"]). About 2.5 minutes plus the machine's start.
set -uo pipefail
exec > >(tee "${OUT:-/tmp}/device_ab.txt") 2>&1
. benches/gpu/device_env.sh
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || true
section() { echo; echo "=== $1 ($SECONDS s)"; }
section "Rust GPU tests"
for b in .devbin/physcore_gpu-tests .devbin/particles-tests .devbin/gray_scott-tests; do
  [ -x "$b" ] && timeout 60 "$b" --test-threads 4 2>&1 | grep -E "test result|FAILED|panicked"
done
[ -x .devbin/physcore_core-lib ] && timeout 60 .devbin/physcore_core-lib device --test-threads 4 2>&1 | grep -E "test result|FAILED|panicked"
section "Python GPU tests"
timeout 90 python3 -m pytest -p no:cacheprovider -o addopts="" -q tests/gpu 2>&1 | tail -3
[ -f .devbin/base_core.abi3.so ] || exit 0
mkdir -p /tmp/base && cp -r python/physcore /tmp/base/ && cp .devbin/base_core.abi3.so /tmp/base/physcore/_core.abi3.so
section "A/B: cloth 256² and 1024², grids 4096² (base, then this tree; 3 rounds)"
for r in 1 2 3; do
  for who in base this; do
    pp="$PWD/python"; [ $who = base ] && pp=/tmp/base
    PYTHONPATH=$pp timeout 40 python3 benches/gpu/bench_gpu_cloth.py --device gpu --n 256,1024 --steps 100 --cpu-max 0 2>&1 | grep -F "²" | sed "s/^/$r $who  /"
    PYTHONPATH=$pp timeout 40 python3 benches/gpu/bench_gpu_grids.py --device gpu --n 4096 --steps 300 --cpu-max 0 2>&1 | grep -F "²" | sed "s/^/$r $who  /"
  done
done
section "done"
