"""Other kinds of x86-64 machine, played on this one: a child process whose numeric libraries take
the kernels another CPU would give them.

The last bits of a frame's floats can depend on the CPU through three libraries, each choosing its
kernels by the CPU when it loads, and each told otherwise by the environment:
- numpy's SIMD loops (exp, log, tan, arctan, arccos, ... have AVX-512 versions): numpy 2.x leaves
  out the dispatched targets named in NPY_DISABLE_CPU_FEATURES (down to its baseline, x86-64-v2);
- OpenBLAS, behind numpy's matmul, dot and 1-D norm: OPENBLAS_CORETYPE names the kernels (Haswell:
  AVX2 and FMA; Sandybridge: AVX; Nehalem: SSE), which differ in FMA and in the order of the sums;
- glibc's libm (math.sin, np.sin, np.arctan2, ...), whose sin, cos, exp, log, pow and tan have FMA
  versions: GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA takes the others.
Embree picks its ISA by the CPU too, and nothing outside its API chooses it (embreex makes its
device with the defaults; no config file is read): the harness cannot play it. The compiled
FRAMING_ONLY frame does not use Embree (its ray casts are camdirector._native's Scene).

`KINDS` are the machines played. `played` says which kernels a child got (so a test can show the
kind took effect), `replay_as` replays a recording in a child of a kind (`camdirector replay`).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

ROOT = Path(__file__).resolve().parents[2]
_NO_FMA = "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F"  # libm's kernels without FMA (glibc >= 2.33 names)


@dataclass(frozen=True)
class MachineKind:
    name: str
    numpy_targets: tuple[str, ...]  # numpy's dispatched SIMD targets the kind has (the rest disabled)
    openblas_core: str  # OPENBLAS_CORETYPE, as OpenBLAS names its kernels
    fma: bool  # whether libm takes its FMA kernels
    needs: tuple[str, ...]  # the CPU features (numpy's names) the kind's kernels run on

    def playable(self) -> bool:
        """Whether this CPU runs the kind's kernels (a kind above this CPU cannot be played here)."""
        return all(__cpu_features__.get(feature, False) for feature in self.needs)

    def env(self) -> dict[str, str]:
        """The environment of a child playing the kind."""
        env = dict(os.environ, OPENBLAS_CORETYPE=self.openblas_core)
        disabled = [t for t in __cpu_dispatch__ if __cpu_features__.get(t, False) and t not in self.numpy_targets]
        if disabled:
            env["NPY_DISABLE_CPU_FEATURES"] = ",".join(disabled)
        else:
            env.pop("NPY_DISABLE_CPU_FEATURES", None)
        if self.fma:
            env.pop("GLIBC_TUNABLES", None)
        else:
            env["GLIBC_TUNABLES"] = _NO_FMA
        return env


KINDS = (
    # as machine.json's AMD EPYC, or any Haswell or Zen: x86-64-v3
    MachineKind("x86-64-v3 (AVX2, FMA: Haswell, Zen)", ("X86_V3",), "Haswell", True, ("AVX2", "FMA3")),
    MachineKind("Sandy Bridge (AVX, no FMA)", (), "SandyBridge", False, ("AVX",)),
    MachineKind("x86-64-v2 (SSE4.2: Nehalem)", (), "Nehalem", False, ()),
)

# What a child prints of its kernels: numpy's active dispatched targets, OpenBLAS's kernel, and a
# digest of libm's sin over a grid (its FMA and plain kernels round some of those differently).
_FINGERPRINT = """
import ctypes, glob, hashlib, json, math, os, struct
import numpy
from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
libs = glob.glob(os.path.join(os.path.dirname(numpy.__file__), os.pardir, "numpy.libs", "libscipy_openblas*.so"))
core = None
if libs:
    corename = ctypes.CDLL(libs[0]).scipy_openblas_get_corename64_
    corename.restype = ctypes.c_char_p
    core = corename().decode()
sines = b"".join(struct.pack("d", math.sin(0.01 * i + 0.0123)) for i in range(20000))
print(json.dumps({
    "numpy": [t for t in __cpu_dispatch__ if __cpu_features__[t]],
    "openblas": core,
    "libm_sin": hashlib.sha1(sines).hexdigest(),
}))
"""


def played(kind: MachineKind | None) -> dict:
    """The kernels a child of `kind` (None: this machine as it is) got (_FINGERPRINT)."""
    env = dict(os.environ) if kind is None else kind.env()
    out = subprocess.run([sys.executable, "-c", _FINGERPRINT], env=env, capture_output=True, text=True, check=True)
    return json.loads(out.stdout)


def replay_as(kind: MachineKind | None, recording: Path, frame_path: str, data_dir: Path) -> dict:
    """`camdirector replay` of `recording` on `frame_path` in a child of `kind` (None: this machine
    as it is): its report ({"frames", "identical", "first_mismatch", "ok"})."""
    env = dict(os.environ) if kind is None else kind.env()
    command = [sys.executable, "-m", "camdirector", "replay", str(recording), "--frame-path", frame_path]
    out = subprocess.run([*command, "--data-dir", str(data_dir)], env=env, capture_output=True, text=True, cwd=ROOT)
    assert out.returncode in (0, 1), out.stderr  # 1: a mismatch, reported; anything else failed
    return json.loads(out.stdout)
