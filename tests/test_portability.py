"""The golden and determinism tests pass on another SIMD path of the same machine.

OpenCV, NumPy and Mesa's llvmpipe renderer choose their vector kernels (SSE, AVX2, AVX-512) by
the CPU at run time, so a rendered frame, its detection and much of the arithmetic round
differently from one machine to another. The golden tests state tolerances justified by physics
for that (``tests/test_golden.py``); here they run again in a fresh interpreter with every
run-time-dispatched kernel of OpenCV and NumPy switched off (``OPENCV_CPU_DISABLE``,
``NPY_DISABLE_CPU_FEATURES``: the SSE baseline only) and llvmpipe's vectors at 128 bits
(``LP_NATIVE_VECTOR_WIDTH``), as on an older CPU. They must pass unchanged.

OpenBLAS's kernel (``OPENBLAS_CORETYPE``) is left as the machine sets it: some of its builds
compute wrong results on kernels the CPU was not probed for.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import pytest

try:
    from numpy._core import _multiarray_umath as umath
except ImportError:
    # NumPy 1.x
    from numpy.core import _multiarray_umath as umath

ROOT = Path(__file__).resolve().parent.parent
PROBE = (
    "import json, cv2\n"
    "try:\n    from numpy._core import _multiarray_umath as u\n"
    "except ImportError:\n    from numpy.core import _multiarray_umath as u\n"
    "print(json.dumps({'cv2': cv2.getCPUFeaturesLine(), "
    "'numpy': [f for f in u.__cpu_dispatch__ if u.__cpu_features__.get(f)]}))"
)


def _opencv_dispatched() -> list[str]:
    """OpenCV's run-time-dispatched features this CPU has (``*NAME`` without ``?``)."""
    line = cv2.getCPUFeaturesLine().split()
    return [f[1:] for f in line if f.startswith("*") and not f.endswith("?")]


def _numpy_dispatched() -> list[str]:
    """NumPy's run-time-dispatched features this CPU has."""
    return [f for f in umath.__cpu_dispatch__ if umath.__cpu_features__.get(f)]


def _baseline_env() -> dict[str, str]:
    """This environment with the dispatched kernels of OpenCV, NumPy and llvmpipe held down."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTEST_")}
    env["OPENCV_CPU_DISABLE"] = ",".join(_opencv_dispatched())
    env["NPY_DISABLE_CPU_FEATURES"] = " ".join(_numpy_dispatched())
    env["LP_NATIVE_VECTOR_WIDTH"] = "128"
    return env


def test_the_baseline_environment_switches_the_dispatched_kernels_off():
    out = subprocess.run(
        [sys.executable, "-c", PROBE],
        env=_baseline_env(),
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    seen = json.loads(out.stdout)
    # OpenCV marks a feature it may not use with "?"; NumPy then dispatches to none
    line = seen["cv2"].split()
    assert all(f"*{f}?" in line for f in _opencv_dispatched()), seen["cv2"]
    assert seen["numpy"] == []


@pytest.mark.slow
def test_golden_and_determinism_pass_on_the_sse_baseline():
    tests = ["tests/test_golden.py", "tests/test_determinism.py"]
    out = subprocess.run(
        [sys.executable, "-m", "pytest", "-n", "0", "-q", "-p", "no:cacheprovider", *tests],
        env=_baseline_env(),
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert " passed" in out.stdout and "failed" not in out.stdout
