"""The release wheels installed as a user would (``pytest -m release``, after ``.ci/release``).

Each x86-64 wheel this machine can run goes into a fresh virtual environment (no system site
packages) with no Rust toolchain on the PATH; the README's first command renders a GIF there and
``wheel_smoke.py`` steps every part family. The manylinux wheel's environment is this Python's;
the musllinux wheel's is made by a musl CPython (``.ci/musl-python`` compiles one, and musl,
from Debian's sources), whose pip installs it offline beside NumPy's, Pillow's and tqdm's
musllinux wheels. The aarch64 wheel is unpacked beside NumPy's aarch64 wheel and run by an
aarch64 CPython under qemu user-mode emulation (``.ci/arm64-python`` makes one from Debian's
arm64 packages), at the NEON level and the scalar level.

Wheels are looked for in ``dist/`` (or ``$PHYSCORE_WHEELS``); a missing wheel, or a missing musl
or aarch64 interpreter, is a failure, not a skip, once this module is selected: the release tests
exist to be run after a release build.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

pytestmark = pytest.mark.release

ROOT = Path(__file__).resolve().parents[2]
WHEELS = Path(os.environ.get("PHYSCORE_WHEELS", ROOT / "dist"))
SMOKE = Path(__file__).resolve().parent / "wheel_smoke.py"
ARM64 = Path(os.environ.get("PHYSCORE_ARM64_ROOT", "/opt/physcore-arm64"))
MUSL = Path(os.environ.get("PHYSCORE_MUSL_ROOT", "/opt/physcore-musl"))


def _wheel(tag: str) -> Path:
    found = sorted(WHEELS.glob(f"physcore-*{tag}*.whl"))
    assert found, f"no {tag} wheel in {WHEELS}: run .ci/release first"
    return found[-1]


def _no_rust_path() -> str:
    """PATH without any directory that holds cargo or rustc."""
    keep = [d for d in os.environ.get("PATH", "").split(os.pathsep)
            if d and not (Path(d, "cargo").exists() or Path(d, "rustc").exists())]
    return os.pathsep.join(keep)


def _elf_sections(data: bytes) -> list[str]:
    """Section names of a 64-bit little-endian ELF file (the shared library in a wheel)."""
    import struct

    assert data[:4] == b"\x7fELF" and data[4] == 2 and data[5] == 1, "not a 64-bit little-endian ELF"
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", data, 0x3A)
    def header(k: int) -> tuple[int, int, int]:
        name, _type, _flags, _addr, offset, size = struct.unpack_from("<IIQQQQ", data, shoff + k * shentsize)
        return name, offset, size
    _, str_off, str_size = header(shstrndx)
    table = data[str_off:str_off + str_size]
    return [table[n:table.index(b"\0", n)].decode() for n, _, _ in (header(k) for k in range(shnum))]


def _elf_interpreter(data: bytes) -> str:
    """The program interpreter (PT_INTERP) of a 64-bit little-endian ELF executable: its libc's loader."""
    import struct

    assert data[:4] == b"\x7fELF" and data[4] == 2 and data[5] == 1, "not a 64-bit little-endian ELF"
    phoff, = struct.unpack_from("<Q", data, 0x20)
    phentsize, phnum = struct.unpack_from("<HH", data, 0x36)
    for k in range(phnum):
        p_type, _flags, offset, _vaddr, _paddr, size = struct.unpack_from("<IIQQQQ", data, phoff + k * phentsize)
        if p_type == 3:  # PT_INTERP
            return data[offset:offset + size].rstrip(b"\0").decode()
    return ""


def _run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=900, **kw)
    assert r.returncode == 0, f"{cmd}: exit {r.returncode}\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
    return r


def test_every_wheel_is_small_stripped_and_licensed():
    for w in sorted(WHEELS.glob("physcore-*.whl")):
        with zipfile.ZipFile(w) as z:
            names = z.namelist()
            assert any(n.endswith(".dist-info/licenses/LICENSE") for n in names), names
            assert any(n.endswith(".dist-info/licenses/LICENSES-THIRD-PARTY") for n in names), names
            # The HTML player's scripts (package data beside the Python: maturin ships the folder).
            for f in ("three.min.js", "OrbitControls.min.js", "GLTFLoader.min.js", "LICENSE-three.js"):
                assert f"physcore/render/_vendor/{f}" in names, (f, w.name)
            assert "physcore/render/_player.js" in names, w.name
            assert b"three.js" in z.read(next(n for n in names if n.endswith(".dist-info/licenses/LICENSES-THIRD-PARTY")))
            (so,) = [n for n in names if n.startswith("physcore/_core") and n.endswith(".so")]
            assert "abi3" in so and "abi3" in w.name, (so, w.name)
            data = z.read(so)
        sections = _elf_sections(data)
        assert not [n for n in sections if n.startswith(".debug") or n == ".symtab"], f"{w.name}: not stripped: {sections}"
        assert w.stat().st_size < 8 * 1024 * 1024, f"{w.name}: {w.stat().st_size} bytes"


@pytest.mark.skipif(sysconfig.get_platform() != "linux-x86_64", reason="x86-64 wheels run on x86-64 Linux")
def test_manylinux_x86_64_wheel_installs_and_runs_without_rust(tmp_path):
    wheel = _wheel("manylinux_2_28_x86_64")
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", str(venv)])
    py = venv / "bin" / "python"
    env = {**os.environ, "PATH": f"{venv / 'bin'}{os.pathsep}{_no_rust_path()}"}
    env.pop("PYTHONPATH", None)
    assert shutil.which("cargo", path=env["PATH"]) is None and shutil.which("rustc", path=env["PATH"]) is None
    _run([str(py), "-m", "pip", "install", "-q", str(wheel)], env=env)
    # The README's first command, from the installed wheel.
    _run([str(venv / "bin" / "physcore"), "render", "cloth", "-o", str(tmp_path / "cloth.gif"), "-q"], env=env, cwd=tmp_path)
    gif = (tmp_path / "cloth.gif").read_bytes()
    assert gif[:6] == b"GIF89a" and len(gif) > 100_000
    r = _run([str(py), str(SMOKE)], env=env, cwd=tmp_path)
    assert r.stdout.rstrip().endswith("all ok"), r.stdout
    # The installed package is the wheel's, not this checkout's.
    r = _run([str(py), "-c", "import physcore; print(physcore.__file__)"], env=env, cwd=tmp_path)
    assert str(venv) in r.stdout


def test_aarch64_wheel_runs_under_qemu(tmp_path):
    wheel = _wheel("manylinux_2_28_aarch64")
    qemu = shutil.which("qemu-aarch64")
    marker = ARM64 / "PYTHON"  # the interpreter's path, written by .ci/arm64-python
    python = Path(marker.read_text().strip()) if marker.exists() else ARM64 / "missing"
    site = ARM64 / "site-packages"
    if qemu is None or not python.exists() or not site.is_dir():
        pytest.fail(f"needs qemu-aarch64 and an aarch64 CPython in {ARM64} (make it with .ci/arm64-python)")
    target = tmp_path / "site"
    with zipfile.ZipFile(wheel) as z:
        z.extractall(target)
    env = {"PYTHONPATH": f"{target}{os.pathsep}{site}", "PATH": "/usr/bin:/bin", "QEMU_LD_PREFIX": str(ARM64)}
    for level in ("neon", "scalar"):
        r = _run([qemu, "-L", str(ARM64), str(python), str(SMOKE)], env={**env, "PHYSCORE_SIMD": level}, cwd=tmp_path)
        assert "all ok" in r.stdout, r.stdout
        assert f"'simd_level': '{level}'" in r.stdout, r.stdout


@pytest.mark.skipif(sysconfig.get_platform() != "linux-x86_64", reason="x86-64 wheels run on x86-64 Linux")
def test_musllinux_wheel_installs_and_runs_under_musl(tmp_path):
    wheel = _wheel("musllinux_1_2_x86_64")
    marker = MUSL / "PYTHON"  # the interpreter's path, written by .ci/musl-python
    python = Path(marker.read_text().strip()) if marker.exists() else MUSL / "missing"
    wheels = MUSL / "wheels"  # NumPy's, Pillow's and tqdm's musllinux wheels: the install is offline
    if not python.exists() or not wheels.is_dir():
        pytest.fail(f"needs a musl CPython in {MUSL} (make it with .ci/musl-python)")
    # A glibc interpreter would prove nothing: musl's loader runs it, and pip's tags say musllinux.
    loader = _elf_interpreter(python.resolve().read_bytes())
    assert Path(loader).name == "ld-musl-x86_64.so.1" and Path(loader).exists(), loader
    venv = tmp_path / "venv"
    _run([str(python), "-m", "venv", str(venv)])
    py = venv / "bin" / "python"
    env = {"PATH": f"{venv / 'bin'}{os.pathsep}{_no_rust_path()}", "HOME": str(tmp_path)}
    assert shutil.which("cargo", path=env["PATH"]) is None and shutil.which("rustc", path=env["PATH"]) is None
    r = _run([str(py), "-c", "from pip._vendor.packaging.tags import sys_tags; print(next(iter(sys_tags())))"], env=env)
    assert "musllinux_1_" in r.stdout, r.stdout
    _run([str(py), "-m", "pip", "install", "-q", "--no-index", "--find-links", str(wheels), str(wheel)], env=env)
    # The README's first command, from the installed wheel.
    _run([str(venv / "bin" / "physcore"), "render", "cloth", "-o", str(tmp_path / "cloth.gif"), "-q"], env=env, cwd=tmp_path)
    gif = (tmp_path / "cloth.gif").read_bytes()
    assert gif[:6] == b"GIF89a" and len(gif) > 100_000
    r = _run([str(py), str(SMOKE)], env=env, cwd=tmp_path)
    assert r.stdout.rstrip().endswith("all ok"), r.stdout
    # The installed package is the wheel's, its extension module musl's build.
    r = _run([str(py), "-c", "import physcore, physcore._core as c; print(physcore.__file__, c.__file__)"], env=env, cwd=tmp_path)
    assert str(venv) in r.stdout and "abi3" in r.stdout, r.stdout
