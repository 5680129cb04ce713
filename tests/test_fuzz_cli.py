"""Hypothesis fuzz of ``cnt-sim`` (issue 14): the arguments of ``run``, ``measure`` and
``sweep``, and the contents of the files they read (traces, sweep CSVs).

Every example drives ``cnt_env.cli.main(argv)`` in-process and asserts the error contract
of docs/cli.md: an exit code from the one table and never the internal-error code, no
traceback, an error message on one ``cnt-sim: error:`` line (or argparse's usage error),
no file touched outside the outputs given, and a bounded time. No simulation ever starts:
``cnt_env.runs.deposit`` is replaced by a fake that returns a short straight trace, the
figure writer by one that writes a few bytes, and the sweep's executors run in-process.

The normal suite runs a few examples per interface (profile ``cli-fast``); ``-m slow``
runs 10 000 per interface (profile ``cli-slow``; ``CNT_FUZZ_EXAMPLES=N`` changes it).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import shutil
import stat
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import cnt_env.plotting
import cnt_env.runs
from cnt_env import cli, sweep, units
from cnt_env.io import save_trace

settings.register_profile(
    "cli-fast",
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    derandomize=True,
)
settings.register_profile(
    "cli-slow",
    max_examples=int(os.environ.get("CNT_FUZZ_EXAMPLES", "10000")),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
FAST = settings.get_profile("cli-fast")
SLOW = settings.get_profile("cli-slow")
#: CPU seconds one command may take (no simulation runs; imports are warm after the
#: first). CPU time, not wall time, so that a busy machine cannot fail the test.
MAX_CPU_SECONDS = 20.0
#: CPU seconds a sweep may add per grid point it plans (each is validated as a run before
#: any work: ~0.2 ms on this machine; a 1e6-point grid, which --max-points allows, plans in
#: minutes, linear in what was asked, while a runaway is caught by the bound above).
PLAN_CPU_SECONDS_PER_POINT = 1e-3
#: Wall seconds, only to catch a command that blocks (a FIFO) rather than computes.
MAX_WALL_SECONDS = 600.0
ALLOWED_CODES = set(cli.EXIT_CODES) - {cli.EXIT_INTERNAL}


# --------------------------------------------------------------------------- harness


class FakeSim:
    """What ``runs.deposit`` returns, without numba: a straight trace along +x."""

    def __init__(self, length: float) -> None:
        n = int(min(max(length, 2.0), 40.0)) + 1
        self._trace = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])
        self.suspended_nodes = np.column_stack([np.zeros(4), np.arange(4.0), np.zeros(4)])

    def trace(self) -> np.ndarray:
        return self._trace.copy()


def fake_deposit(config: Any, length: float, seed: int = 0, progress: Any = None):
    if progress is not None:
        progress(min(length, 1.0), length)
        progress(length, length)
    stats = {"deposited_length": float(length), "time": 1.0, "steps": 2,
             "newton_iterations": 4, "wall_time_s": 0.0}  # fmt: skip
    return FakeSim(length), stats


def fake_plot_run(trace: Any, suspended: Any, measurement: Any, path: Any, **kw: Any) -> Path:
    Path(path).write_bytes(b"\x89PNG fake")
    return Path(path)


def fake_run_point(point: sweep.SweepPoint) -> dict:
    row = {name: math.nan for name in sweep.RESULT_COLUMNS}
    row.update(dict(point.values), seed=point.seed, pattern="coil", failure="")
    row.update(config_hash=point.config_hash, wall_time_s=0.0)
    return row


def _serial(points: Any, jobs: int, *rest: Any) -> None:
    on_result = rest[-1]
    for point in points:
        on_result(point, sweep.run_point_safe(point))


@pytest.fixture(scope="module")
def no_work() -> Iterator[None]:
    """No simulation, no figure, no worker process, no Ray, for the whole module."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cnt_env.runs, "deposit", fake_deposit)
        mp.setattr(cnt_env.plotting, "plot_run", fake_plot_run)
        mp.setattr(sweep, "run_point", fake_run_point)
        mp.setattr(sweep, "_run_processes", _serial)
        mp.setattr(sweep, "_run_ray", lambda points, jobs, address, on_result: _serial(
            points, jobs, on_result))  # fmt: skip
        mp.setattr(sweep, "import_ray", lambda: None)
        mp.setattr(sweep, "plot_sweep", lambda *a, **k: [])
        yield


def _snapshot(root: Path) -> dict[str, tuple]:
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st_ = p.lstat()
            out[str(p.relative_to(root))] = (st_.st_mode, st_.st_size, st_.st_mtime_ns)
    return out


def _call(argv: list[str]) -> tuple[int, str, str, tuple[float, float]]:
    """Exit code, stdout, stderr and (CPU seconds, wall seconds) of one command."""
    out, err = io.StringIO(), io.StringIO()
    cpu, wall = time.process_time(), time.monotonic()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(argv)
    seconds = (time.process_time() - cpu, time.monotonic() - wall)
    return code, out.getvalue(), err.getvalue(), seconds


@contextlib.contextmanager
def _workdir() -> Iterator[tuple[Path, dict[str, Path]]]:
    """A fresh folder with the hostile paths an output flag may name, removed on exit,
    also when hypothesis stops an example in a draw (which used to leave it behind)."""
    root = Path(tempfile.mkdtemp(prefix="fuzz-"))
    try:
        (root / "dir").mkdir()
        (root / "keep.txt").write_text("keep")
        (root / "link.npz").symlink_to(root / "keep.txt")
        (root / "dangling.png").symlink_to(root / "nowhere")
        os.mkfifo(root / "fifo")
        named = {
            "new": root / "out.npz",
            "nested": root / "sub" / "deeper" / "o.png",
            "dir": root / "dir",
            "link": root / "link.npz",
            "dangling": root / "dangling.png",
            "fifo": root / "fifo",
            "long": root / ("n" * 300),
            "keep": root / "keep.txt",
        }
        yield root, named
    finally:
        shutil.rmtree(root, ignore_errors=True)


def _check_outcome(code: int, stdout: str, stderr: str, seconds: tuple[float, float]) -> None:
    assert code in ALLOWED_CODES, (code, stderr)
    assert "Traceback" not in stderr and "Traceback" not in stdout
    if code != 0:
        lines = stderr.strip().splitlines()
        assert lines, "an error exit without a message"
        last = lines[-1]
        assert (last.startswith("cnt-sim") and "error:" in last) or "interrupted" in last, stderr
    points = 0
    if code == 0 and stdout.startswith("{"):  # a sweep's --json summary: the points planned
        points = len(json.loads(stdout.splitlines()[0]).get("rows", ()))
    budget = MAX_CPU_SECONDS + PLAN_CPU_SECONDS_PER_POINT * points
    assert seconds[0] < budget and seconds[1] < MAX_WALL_SECONDS, (seconds, points)


def _check_untouched(root: Path, before: dict[str, tuple], outputs: set[str]) -> None:
    """Every entry that changed is one of the outputs given (or its .json, or a folder
    created for it); the link targets, the FIFO and the files kept are as they were."""
    after = _snapshot(root)
    allowed = set()
    for o in outputs:
        rel = Path(o)
        allowed |= {str(rel), f"{rel}.json"}
        allowed |= {str(p) for p in rel.parents if str(p) != "."}
        stem = str(rel.with_suffix(""))
        allowed |= {f"{stem}_curves.png", f"{stem}_phase.png"}
        allowed |= {str(rel.parent / f"{rel.stem}_curves.png"),
                    str(rel.parent / f"{rel.stem}_phase.png")}  # fmt: skip
    for key in set(before) | set(after):
        if key == "plots" or key.startswith("plots/"):
            continue  # --plots DIR: the sweep's figures
        if before.get(key) != after.get(key):
            assert key in allowed, (key, before.get(key), after.get(key), outputs)
    assert "keep.txt" in outputs or (root / "keep.txt").read_bytes() == b"keep"
    assert stat.S_ISFIFO((root / "fifo").lstat().st_mode)
    assert (root / "link.npz").is_symlink()


# --------------------------------------------------------------------------- strategies

NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-300, 1e300, -1.0, 5.0, 40.0, 1e-9, 0.2, 2.0, 1e7]),
    st.integers(-(10**12), 10**12),
)
TEXT_VALUES = st.one_of(
    NUMBERS.map(repr),
    st.text(max_size=12),
    st.sampled_from(["nan", "inf", "-inf", "", "1e", "0x10", "1,2", "--json", "1:2:3"]),
)
INT_VALUES = st.one_of(st.integers(-5, 10**9).map(str), TEXT_VALUES)
PATH_KEYS = st.sampled_from(["new", "nested", "dir", "link", "dangling", "fifo", "long", "keep"])
SPECIAL = st.sampled_from(["/dev/null", "/dev/full", "/proc/x.npz", "/proc/self/x", ""])

RUN_FLOAT_FLAGS = ["--Hbar", "--Ibar", "--vbar", "--phi", "--kappa-c", "--delta", "--dt",
                   "--deposit", "--transient", "--kb", "--ev", "--rho", "--mu", "--H", "--v",
                   "--coarse-delta", "--fine-length", "--initial-radius", "--cohesive-range",
                   "--friction", "--max-wall-time"]  # fmt: skip
RUN_INT_FLAGS = ["--seed", "--max-nodes", "--max-steps"]
CHOICES = {
    "--preset": ["coil", "serpentine", "x"],
    "--substrate": ["flat", "stepped", "steep"],
    "--drag-law": ["linear", "printed", "x"],
    "--sliding": ["B", "C", "none", "D"],
    "--contact-mode": ["event", "project", "x"],
    "--adhesion": ["eq1", "cohesive", "x"],
}


@st.composite
def run_argv(draw: Any, named: dict[str, Path]) -> list[str]:
    """``run`` flags, a few of them hostile; a tiny --deposit unless it is fuzzed."""
    argv: list[str] = ["run", "--json"] if draw(st.booleans()) else ["run"]
    for flag in draw(st.lists(st.sampled_from(RUN_FLOAT_FLAGS), max_size=4)):
        argv.append(f"{flag}={draw(TEXT_VALUES)}")
    for flag in draw(st.lists(st.sampled_from(RUN_INT_FLAGS), max_size=2)):
        argv.append(f"{flag}={draw(INT_VALUES)}")
    for flag in draw(st.lists(st.sampled_from(sorted(CHOICES)), max_size=2)):
        argv.append(f"{flag}={draw(st.sampled_from(CHOICES[flag]))}")
    if not any(a.startswith("--deposit") for a in argv):
        argv.append("--deposit=3")
    for flag in draw(st.lists(st.sampled_from(["--out", "--png"]), max_size=2, unique=True)):
        if draw(st.integers(0, 4)) == 0:
            argv.append(f"{flag}={draw(SPECIAL)}")
        else:
            argv.append(f"{flag}={named[draw(PATH_KEYS)]}")
    return argv


def _relative(root: Path, argv: list[str]) -> set[str]:
    """The outputs an argv names, relative to ``root``."""
    found = set()
    for a in argv:
        for flag in ("--out=", "--png=", "--plots="):
            if a.startswith(flag):
                value = a[len(flag) :]
                with contextlib.suppress(ValueError):
                    found.add(str(Path(value).relative_to(root)))
    return found


def _check_example(argv: list[str], root: Path) -> None:
    before = _snapshot(root)
    for special in ("/dev/null", "/dev/full"):
        assert stat.S_ISCHR(os.stat(special).st_mode)
    code, stdout, stderr, seconds = _call(argv)
    _check_outcome(code, stdout, stderr, seconds)
    _check_untouched(root, before, _relative(root, argv))
    for special in ("/dev/null", "/dev/full"):
        assert stat.S_ISCHR(os.stat(special).st_mode)
    assert not [p for p in root.rglob(".*.part*")], "a temporary output was left behind"


def _fuzz_run(data: st.DataObject) -> None:
    with _workdir() as (root, named):
        _check_example(data.draw(run_argv(named)), root)


# --------------------------------------------------------------------------- files


@pytest.fixture(scope="module")
def trace_bytes(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tmp_path_factory.mktemp("trace") / "t.npz"
    sim, stats = fake_deposit(None, 30.0)
    config = {"preset": "coil", "substrate": "flat", "transient_length": 0.0, "seed": 0}
    save_trace(path, sim.trace(), units.paper_groups("coil"), config, stats, sim.suspended_nodes)
    return path.read_bytes()


WRONG_VALUES = st.one_of(
    st.just(np.array([1, 2, 3])),
    st.just(np.array(["a", "b"])),
    st.just(np.zeros((2, 2, 2))),
    st.just(np.array(3.5)),
    st.just(np.array(b"bytes")),
    st.just(np.array("not json {")),
    st.just(np.array("[1, 2]")),
    st.builds(lambda d: np.array(json.dumps(d)), st.dictionaries(
        st.sampled_from(["steps", "time", "preset", "substrate", "transient_length", "phi",
                         "Hbar", "seed", "si", "deposited_length"]),
        st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=5),
                  st.lists(st.integers(), max_size=2)), max_size=4)),
)  # fmt: skip


@st.composite
def trace_file(draw: Any, good: bytes) -> bytes | dict:
    """Bytes of a damaged trace file, or the entries of one with wrong dtypes."""
    kind = draw(st.sampled_from(["random", "truncated", "flipped", "appended", "entries"]))
    if kind == "random":
        return draw(st.binary(max_size=512))
    if kind == "truncated":
        return good[: draw(st.integers(0, len(good)))]
    if kind == "flipped":
        data = bytearray(good)
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, len(data) - 1))
            data[i] = draw(st.integers(0, 255))
        return bytes(data)
    if kind == "appended":
        return good + draw(st.binary(min_size=1, max_size=64))
    with np.load(io.BytesIO(good)) as npz:
        entries = dict(npz)
    for key in draw(st.lists(st.sampled_from(sorted(entries)), min_size=1, max_size=3)):
        entries[key] = draw(WRONG_VALUES)
    return entries


def _fuzz_measure(data: st.DataObject, good: bytes) -> None:
    with _workdir() as (root, named):
        content = data.draw(trace_file(good))
        path = root / "in.npz"
        if isinstance(content, dict):
            np.savez(path, **content)
        else:
            path.write_bytes(content)
        argv = ["measure", str(path)]
        if data.draw(st.booleans()):
            argv.append(f"--transient={data.draw(TEXT_VALUES)}")
        if data.draw(st.booleans()):
            argv.append(f"--png={named[data.draw(PATH_KEYS)]}")
        if data.draw(st.booleans()):
            argv.append("--json")
        _check_example(argv, root)


# --------------------------------------------------------------------------- sweep

PARAMS = st.one_of(
    st.sampled_from(["Ibar", "vbar", "Hbar", "kappa-c", "delta", "sigma", "r0_bar", "phi"]),
    st.sampled_from(["Ibar", "vbar", "phi"]),  # half of the sweeps are valid grids
    st.text(max_size=8),
)
VALUES = st.one_of(
    st.lists(st.sampled_from(["0.01", "0.5", "100", "200.5"]), min_size=1, max_size=3).map(
        ",".join
    ),
    st.lists(NUMBERS.map(repr), min_size=1, max_size=3).map(",".join),
    st.text(max_size=12),
)
RANGES = st.one_of(
    st.tuples(NUMBERS, NUMBERS, st.integers(-2, 10**9), st.sampled_from(["", ":log", ":x"])).map(
        lambda t: f"{t[0]!r}:{t[1]!r}:{t[2]}{t[3]}"
    ),
    st.text(max_size=12),
)
CSV_CONTENT = st.one_of(
    st.binary(max_size=256),
    st.text(max_size=256).map(str.encode),
    st.sampled_from([b'Ibar,seed,pattern\n100.0,0,"coil', b"\xff\xfe\x00", b"\n\n", b"a,b\n"]),
)


def _fuzz_sweep(data: st.DataObject) -> None:
    with _workdir() as (root, named):
        argv = ["sweep", "--Hbar=30", "--deposit=3", "--no-plots" if data.draw(st.booleans())
                else f"--plots={root / 'plots'}", "--json"]  # fmt: skip
        argv.append(f"--param={data.draw(PARAMS)}")
        if data.draw(st.booleans()):
            argv.append(f"--values={data.draw(VALUES)}")
        else:
            argv.append(f"--range={data.draw(RANGES)}")
        if data.draw(st.booleans()):
            argv += [f"--param2={data.draw(PARAMS)}", f"--values2={data.draw(VALUES)}"]
        for flag in data.draw(st.lists(st.sampled_from(["--repeats", "--jobs", "--seed",
                                                        "--max-points"]), max_size=2)):  # fmt: skip
            argv.append(f"{flag}={data.draw(INT_VALUES)}")
        for flag in data.draw(st.lists(st.sampled_from(RUN_FLOAT_FLAGS[:9]), max_size=2)):
            argv.append(f"{flag}={data.draw(TEXT_VALUES)}")
        if data.draw(st.booleans()):
            argv.append(f"--backend={data.draw(st.sampled_from(['local', 'ray', 'x']))}")
        choice = data.draw(st.integers(0, 3))
        if choice == 0:
            out = root / "s.csv"
            out.write_bytes(data.draw(CSV_CONTENT))
        elif choice == 1:
            out = named[data.draw(PATH_KEYS)]
        elif choice == 2:
            out = Path(data.draw(SPECIAL) or "/proc/x.csv")
        else:
            out = root / "new.csv"
        argv.append(f"--out={out}")
        # bounded sweep size: a drawn --max-points (up to 1e9) is refused over
        # sweep.MAX_POINTS_CEILING before any grid is built
        _check_example(argv, root)


# --------------------------------------------------------------------------- tests


@FAST
@given(data=st.data())
def test_fuzz_run_arguments(no_work: None, data: st.DataObject) -> None:
    _fuzz_run(data)


@FAST
@given(data=st.data())
def test_fuzz_measure_files(no_work: None, trace_bytes: bytes, data: st.DataObject) -> None:
    _fuzz_measure(data, trace_bytes)


@FAST
@given(data=st.data())
def test_fuzz_sweep_arguments_and_csv(no_work: None, data: st.DataObject) -> None:
    _fuzz_sweep(data)


@pytest.mark.slow
@SLOW
@given(data=st.data())
def test_fuzz_run_arguments_slow(no_work: None, data: st.DataObject) -> None:
    _fuzz_run(data)


@pytest.mark.slow
@SLOW
@given(data=st.data())
def test_fuzz_measure_files_slow(no_work: None, trace_bytes: bytes, data: st.DataObject) -> None:
    _fuzz_measure(data, trace_bytes)


@pytest.mark.slow
@SLOW
@given(data=st.data())
def test_fuzz_sweep_arguments_and_csv_slow(no_work: None, data: st.DataObject) -> None:
    _fuzz_sweep(data)
