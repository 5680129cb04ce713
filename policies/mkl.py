"""MKL's code path pinned before torch runs, so a trained agent acts alike on every CPU.

On x86, torch's matrix products are Intel MKL's, and MKL picks a code path per CPU
(SSE, AVX2, AVX-512) whose sums round differently in the last bit; a deposition is
chaotic and carries that bit into a different trace within a few control steps
(docs/architecture.md, "Determinism"). Measured on an Intel Xeon with AVX-512: the
shipped agents' actions for the same observations differ in their bits between MKL's
own choice and ``MKL_ENABLE_INSTRUCTIONS=AVX2``, and are the same under both (and under
SSE4_2) with ``MKL_CBWR=COMPATIBLE`` (tests/test_numerics.py). That branch is MKL's
"conditional numerical reproducibility" mode for every Intel-compatible CPU.

Importing :mod:`policies` sets ``MKL_CBWR=COMPATIBLE`` unless the variable is already
set (``MKL_CBWR=AUTO`` restores MKL's own choice). MKL reads it at its first call, so it
takes effect only if nothing in the process ran a torch matrix product before; import
``policies`` first (``cnt-train`` and ``cnt-evaluate`` do). :func:`check` (run by
:func:`policies.load_policy` and ``cnt-train``) reads the branch MKL actually runs and
warns when it is not the one asked for, which is what a torch product run before
``policies`` was imported leaves behind. The cost: a PPO minibatch
step of the shipped network (84-64-64-2, batch 128) takes ~0.93 ms against ~0.75 ms, a
single action ~28 µs against ~30 µs; a control step of the simulator (~70 ms on the
surrogate, ~450 ms on the model) dominates both.
"""

from __future__ import annotations

import ctypes
import functools
import os
import warnings
from collections.abc import Callable
from pathlib import Path

#: The MKL branch importing :mod:`policies` asks for (unless ``MKL_CBWR`` is set).
BRANCH = "COMPATIBLE"

os.environ.setdefault("MKL_CBWR", BRANCH)

#: mkl_service.h: the mask of MKL_CBWR's branch field, and the names of its codes that
#: are not a fixed instruction set (read back on an AMD EPYC: unset 1, AUTO 2,
#: COMPATIBLE 3, and AUTO for an instruction set MKL does not pin on that CPU).
_BRANCH_MASK = 1
_NAMES = {1: "OFF", 2: "AUTO", 3: "COMPATIBLE"}


@functools.cache
def _cbwr_get() -> Callable[[int], int] | None:
    """MKL's ``mkl_serv_cbwr_get`` in torch's library, or None where it has none (not x86,
    not Linux)."""
    try:
        import torch

        lib = ctypes.CDLL(str(Path(torch.__file__).parent / "lib" / "libtorch_cpu.so"))
        get = lib.mkl_serv_cbwr_get
    except (ImportError, OSError, AttributeError):
        return None
    get.restype, get.argtypes = ctypes.c_int, [ctypes.c_int]
    return get


def active_branch() -> str | None:
    """The branch MKL runs in this process ("COMPATIBLE", "AUTO", "OFF": MKL's own choice,
    or ``"code N"``), or None where torch's library has no MKL service. Reading it fixes
    it: MKL settles its branch at its first call."""
    get = _cbwr_get()
    if get is None:
        return None
    code = get(_BRANCH_MASK)
    return _NAMES.get(code, f"code {code}")


def check() -> str | None:
    """Warn if ``MKL_CBWR`` asks for :data:`BRANCH` and MKL runs another (a torch matrix
    product ran before :mod:`policies` was imported); return the active branch."""
    active = active_branch()
    asked = os.environ.get("MKL_CBWR", "").split(",")[0].strip().upper()
    if active is not None and asked == BRANCH and active != BRANCH:
        warnings.warn(f"MKL runs its {active} branch, not {BRANCH}: a torch matrix product "
                      "ran before `policies` was imported, so a trained agent's actions may "
                      "differ in the last bit from another CPU's. Import `policies` first, "
                      f"or set MKL_CBWR={BRANCH} in the environment", stacklevel=2)  # fmt: skip
    return active
