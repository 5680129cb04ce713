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
``policies`` first (``cnt-train`` and ``cnt-evaluate`` do). The cost: a PPO minibatch
step of the shipped network (84-64-64-2, batch 128) takes ~0.93 ms against ~0.75 ms, a
single action ~28 µs against ~30 µs; a control step of the simulator (~70 ms on the
surrogate, ~450 ms on the model) dominates both.
"""

from __future__ import annotations

import os

#: The MKL branch importing :mod:`policies` asks for (unless ``MKL_CBWR`` is set).
BRANCH = "COMPATIBLE"

os.environ.setdefault("MKL_CBWR", BRANCH)
