"""Rollouts with the same bits on every CPU (cnt_env/numerics.py, policies/mkl.py).

NumPy's ``@``/``dot``/``linalg.norm`` run OpenBLAS kernels chosen per CPU, and torch's
matrix products MKL code paths chosen per CPU; both round differently in the last bit.
The rollout's path (simulator, route task, scripted policies) avoids BLAS, and importing
``policies`` pins MKL's path. Checked here by playing the shipped residual agent under
two OpenBLAS kernel sets and two MKL instruction sets (``OPENBLAS_CORETYPE``,
``MKL_ENABLE_INSTRUCTIONS``, which emulate other CPUs on this one): before the change the
observations parted after the first control step."""

from __future__ import annotations

import ast
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cnt_env import numerics

ROOT = Path(__file__).resolve().parents[1]
#: The rollout's path: a BLAS call here makes the trace depend on the CPU.
ROLLOUT_PATH = ("cnt_env/sim", "cnt_env/rod", "cnt_env/task", "policies")
BLAS_ATTRIBUTES = {"dot", "matmul", "inner", "vdot", "tensordot", "linalg"}


def test_dot_and_norm_are_the_closed_forms() -> None:
    a, b = np.array([1.0, 2.0, 3.0]), np.array([4.0, -5.0, 6.0])
    assert numerics.dot(a, b) == 12.0
    assert numerics.norm(np.array([3.0, 4.0])) == 5.0
    assert numerics.norm(np.zeros(3)) == 0.0
    assert numerics.dot(np.array([0.5, 2.0, 8.0]), np.array([True, False, True])) == 8.5
    assert isinstance(numerics.dot(a, b), float)


def test_rows_dot_and_rotate_agree_with_the_matrix_products() -> None:
    rng = np.random.default_rng(1)
    m, v = rng.standard_normal((50, 2)), rng.standard_normal(2)
    np.testing.assert_allclose(numerics.rows_dot(m, v), m @ v, rtol=0, atol=1e-14)
    for heading in (0.0, 0.3, math.pi / 2, -2.0):
        c, s = math.cos(heading), math.sin(heading)
        np.testing.assert_allclose(numerics.rotate(m, heading),
                                   m @ np.array([[c, s], [-s, c]]), rtol=0, atol=1e-14)  # fmt: skip
    np.testing.assert_allclose(numerics.rotate([[1.0, 0.0]], math.pi / 2), [[0.0, 1.0]],
                               atol=1e-16)  # fmt: skip
    # a rotation keeps lengths
    turned = numerics.rotate(m, 0.7)
    np.testing.assert_allclose(np.hypot(*turned.T), np.hypot(*m.T), rtol=1e-15)


def blas_calls(source: str, name: str) -> list[str]:
    """``name:line: what`` for every ``@``, ``.dot``/``matmul``/... or ``linalg`` use."""
    found = []
    for node in ast.walk(ast.parse(source)):
        what = None
        if isinstance(node, ast.BinOp | ast.AugAssign) and isinstance(node.op, ast.MatMult):
            what = "@"
        elif isinstance(node, ast.Attribute) and node.attr in BLAS_ATTRIBUTES:
            owner = node.value
            if not (isinstance(owner, ast.Name) and owner.id == "numerics"):
                what = node.attr
        if what:
            found.append(f"{name}:{node.lineno}: {what}")
    return found


def test_the_rollout_path_calls_no_blas() -> None:
    files = [p for d in ROLLOUT_PATH for p in sorted((ROOT / d).rglob("*.py"))]
    assert len(files) > 20
    found = [hit for p in files for hit in blas_calls(p.read_text(), str(p.relative_to(ROOT)))]
    assert not found, ("BLAS on the rollout's path (use cnt_env.numerics: its sums have "
                       "the same bits on every CPU):\n" + "\n".join(found))  # fmt: skip


def test_the_scan_finds_blas() -> None:
    """The scan above can fail: it sees each form it looks for, and lets numerics pass."""
    source = ("import numpy as np\nnp.dot(a, b)\nc = a @ b\nc @= b\nx.dot(y)\n"
              "np.linalg.norm(v)\nnp.matmul(a, b)\nnumerics.dot(a, b)\n")  # fmt: skip
    assert sorted(h.split(": ")[1] for h in blas_calls(source, "sample")) == [
        "@",
        "@",
        "dot",
        "dot",
        "linalg",
        "matmul",
    ]


#: tests.portable_rollout's digests of the shipped residual agent's first control steps
#: (observation, then action and observation per step), recorded on an AMD EPYC without
#: AVX-512 (2026-12-08). The committed held-out table was laid on an Intel Xeon with
#: AVX-512, and the EPYC lays its episodes to every digit, this one among them
#: (training/results/route_runs/portable_2026-12-08/).
RECORDED_ROLLOUT = ["ef013525b35efb35", "2031d37ae3cf7113", "fbc67df571d4b020",
                    "b77491510386b3aa", "265d8f7596375b64", "b77491510386b3aa",
                    "ca6420c288087efd"]  # fmt: skip


def _run(args: list[str], env_vars: dict[str, str], cache: Path) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_CORETYPE", "MKL_ENABLE_INSTRUCTIONS", "MKL_CBWR")}  # fmt: skip
    env.update(env_vars, CNT_ENV_CACHE_DIR=str(cache), PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip


def _results(procs: list[subprocess.Popen]) -> list[dict]:
    out = []
    for p in procs:
        stdout, stderr = p.communicate(timeout=600)
        assert p.returncode == 0, stderr[-2000:]
        out.append(json.loads(stdout.strip().splitlines()[-1]))
    return out


def _free_mkl(kernels: list[dict[str, str]], tmp_path: Path) -> list[str]:
    """The MKL canary under each kernel set with MKL's own choice (``MKL_CBWR=AUTO``): the
    power of a check, since the sets must differ there for the pin to matter."""
    procs = [_run(["-m", "tests.portable_rollout", "canary"], {"MKL_CBWR": "AUTO", **k},
                  tmp_path) for k in kernels]  # fmt: skip
    return [r["mkl"] for r in _results(procs)]


def test_mkl_runs_the_pinned_branch_and_a_late_pin_is_reported(tmp_path) -> None:
    """policies.mkl.check reads the branch MKL runs: the pinned one when ``policies`` is
    imported first, and a warning (an error here) when a torch product ran before."""
    product = "torch.ones(4, 4) @ torch.ones(4, 4)"
    strict = "import json, warnings; warnings.simplefilter('error'); "
    first = _run(["-c", f"{strict}import policies, torch; {product}; "
                        "print(json.dumps(policies.mkl.check()))"], {}, tmp_path)  # fmt: skip
    late = _run(["-c", f"{strict}import torch; {product}; import policies; "
                       "print(json.dumps(policies.mkl.check()))"], {}, tmp_path)  # fmt: skip
    (pinned,) = _results([first])
    if pinned is None:
        pytest.skip("torch's library has no MKL service on this machine")
    assert pinned == "COMPATIBLE"
    _, stderr = late.communicate(timeout=600)
    assert late.returncode != 0
    assert "Import `policies` first" in stderr and "not COMPATIBLE" in stderr


def test_a_rollout_has_the_same_bits_under_other_blas_and_mkl_kernels(tmp_path) -> None:
    """The shipped residual agent (its follower base, the simulator, the route task and
    torch) on detour_block, from a cold warm-state cache, under two kernel sets."""
    kernels = [{"OPENBLAS_CORETYPE": "Haswell", "MKL_ENABLE_INSTRUCTIONS": "AVX2"},
               {"OPENBLAS_CORETYPE": "Prescott", "MKL_ENABLE_INSTRUCTIONS": "SSE4_2"}]  # fmt: skip
    procs = [_run(["-m", "tests.portable_rollout"], k, tmp_path / f"cache{i}")
             for i, k in enumerate(kernels)]  # fmt: skip
    a, b = _results(procs)
    assert a["rollout"] == RECORDED_ROLLOUT, (
        "this machine lays other bits than the CPUs that laid the committed held-out table "
        "(an Intel Xeon, an AMD EPYC): that table will not repeat to the digit here "
        "(docs/architecture.md, 'Determinism')")  # fmt: skip
    free_bits = _free_mkl(kernels, tmp_path)
    blas_differs, mkl_differs = a["blas"] != b["blas"], free_bits[0] != free_bits[1]
    if not (blas_differs or mkl_differs):
        pytest.skip("this machine's OpenBLAS and MKL give one result under both kernel sets, "
                    "so the check would prove nothing here")  # fmt: skip
    assert a["mkl"] == b["mkl"], "MKL's code path is not pinned (policies/mkl.py)"
    assert len(a["rollout"]) == 7
    assert a["rollout"] == b["rollout"]


@pytest.mark.slow
def test_training_has_the_same_bits_under_other_kernels(tmp_path) -> None:
    """One PPO update of the demo's residual recipe (rollouts, the learner's matrix
    products and Adam) gives the same weights under an emulated CPU; without the MKL pin
    the weights differ (measured: one update of 1 024 samples, 2026-12-08)."""
    emulated = {"OPENBLAS_CORETYPE": "Prescott", "MKL_ENABLE_INSTRUCTIONS": "AVX2",
                "ATEN_CPU_CAPABILITY": "avx2"}  # fmt: skip
    runs = [({}, "own"), (emulated, "emulated")]
    procs = [_run(["-m", "tests.portable_rollout", "train", str(tmp_path / name)], env,
                  tmp_path / f"cache_{name}") for env, name in runs]  # fmt: skip
    own, other = _results(procs)
    free_bits = _free_mkl([env for env, _ in runs], tmp_path)
    if free_bits[0] == free_bits[1]:
        pytest.skip("MKL runs one code path under both kernel sets on this machine")
    assert own["weights"] == other["weights"]
