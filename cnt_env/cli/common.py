"""What every ``cnt-sim`` subcommand shares: the error contract, the exit codes, output
helpers and the flags common to ``run`` and ``sweep``.

Exit codes (docs/cli.md), the one table every command uses:

====  ====================  ==========================================================
code  name                  meaning
====  ====================  ==========================================================
0     ``EXIT_OK``           success
1     ``EXIT_FAILED``       a simulation or measurement failed, a sweep point failed,
                            or an output could not be written
2     ``EXIT_USAGE``        bad input: a flag, a parameter outside its range, an
                            unreadable input file or an output path that cannot be
                            written safely (found before any simulation work)
3     ``EXIT_LIMIT``        a run was stopped by a limit (``--max-steps``,
                            ``--max-wall-time``)
70    ``EXIT_INTERNAL``     an unexpected error (a bug: please report it); still no
                            traceback unless ``CNT_SIM_TRACEBACK=1``
130   ``EXIT_INTERRUPTED``  Ctrl-C; outputs are left as they were
====  ====================  ==========================================================

Every error is one line on stderr, ``cnt-sim: error: <message>``, and the message names
the flag or the input file concerned.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any

from cnt_env.io import package_version, to_jsonable
from cnt_env.presets import FLOW_PROFILES, MESH, MODEL, SETTLED_FRACTION
from cnt_env.runs import ADHESION_MODELS, CONTACT_MODES, DRAG_LAWS, SLIDING_OPTIONS, Limits

PROG = "cnt-sim"
DIST_NAME = "cnt-env"

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2  # argparse's code too
EXIT_LIMIT = 3
EXIT_INTERNAL = 70
EXIT_INTERRUPTED = 130

#: The exit-code table (code -> meaning), as in docs/cli.md.
EXIT_CODES: dict[int, str] = {
    EXIT_OK: "success",
    EXIT_FAILED: "a simulation, measurement, sweep point or output write failed",
    EXIT_USAGE: "bad input (flag, parameter, input file, output path)",
    EXIT_LIMIT: "a run was stopped by a limit",
    EXIT_INTERNAL: "unexpected error (a bug)",
    EXIT_INTERRUPTED: "interrupted",
}

__all__ = [
    "EXIT_CODES",
    "EXIT_FAILED",
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_LIMIT",
    "EXIT_OK",
    "EXIT_USAGE",
    "PROG",
    "CliError",
    "add_group_arguments",
    "add_limit_arguments",
    "add_model_arguments",
    "add_settled_argument",
    "csv_list",
    "float_list",
    "int_list",
    "name_list",
    "package_version",
    "positive_float",
    "positive_int",
    "print_json",
    "progress_bar",
    "require_rerun",
    "seed_int",
    "seed_list",
    "warn",
]


class CliError(Exception):
    """Reported as ``cnt-sim: error: <message>`` with exit code ``code``."""

    def __init__(self, message: str, code: int = EXIT_USAGE) -> None:
        super().__init__(message)
        self.code = code


def require_rerun() -> None:
    """Fail before any work when the optional rerun extra is missing."""
    from cnt_env.replay import import_rerun

    try:
        import_rerun()
    except ImportError as exc:
        raise CliError(str(exc), EXIT_FAILED) from exc


def double_dash_option(
    parser: argparse.ArgumentParser, args: argparse.Namespace, argv: Sequence[str]
) -> str | None:
    """The option given ``--`` as its value (``--opt=--``), else None. argparse reads
    ``--`` as the end of options and stores [] for a single-valued option, which crashes
    further on; an option whose default is a list (``nargs="*"``) may be [] by right.
    Shared by cnt-sim (``app.main``) and the training CLIs (``training.common.parse_cli``).
    """
    if not any(  # [] only: an option's type may itself make a list (seed_list)
        isinstance(v, list) and not v and not isinstance(parser.get_default(k), list)
        for k, v in vars(args).items()
    ):
        return None
    flags = [a.split("=", 1)[0] for a in argv if a.startswith("-") and a.endswith("=--")]
    return flags[0] if flags else "an option"


def warn(message: str) -> None:
    print(f"{PROG}: warning: {message}", file=sys.stderr)


# argparse types shared by cnt-sim, the training CLIs and the benchmarks: a bad value
# is one line naming the flag (argparse adds it), never a traceback.


def positive_int(text: str) -> int:
    """argparse type: an integer ≥ 1."""
    value = _number(int, text, "an integer")
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def nonnegative_int(text: str) -> int:
    """argparse type: an integer ≥ 0 (a count that may be zero, e.g. a lookahead horizon)."""
    value = _number(int, text, "an integer")
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (a time, a budget)."""
    value = _number(float, text, "a number")
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def seed_int(text: str) -> int:
    """argparse type: a seed, an integer ≥ 0 (gymnasium and numpy refuse negative seeds)."""
    value = _number(int, text, "an integer")
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed must be ≥ 0, got {text}")
    return value


def csv_list(text: str) -> list[str]:
    """The items of a comma-separated list, stripped, empty items dropped."""
    return [x.strip() for x in text.split(",") if x.strip()]


def name_list(text: str) -> list[str]:
    """argparse type: comma-separated names, at least one."""
    names = csv_list(text)
    if not names:
        raise argparse.ArgumentTypeError("give at least one name (comma separated)")
    return names


def seed_list(text: str) -> list[int]:
    """argparse type: comma-separated seeds (each ≥ 0), at least one."""
    seeds = [seed_int(x) for x in csv_list(text)]
    if not seeds:
        raise argparse.ArgumentTypeError("give at least one seed")
    return seeds


def int_list(text: str) -> list[int]:
    """argparse type: comma-separated integers ≥ 1 (sizes, counts), at least one."""
    values = [positive_int(x) for x in csv_list(text)]
    if not values:
        raise argparse.ArgumentTypeError("give at least one integer (comma separated)")
    return values


def float_list(text: str) -> list[float]:
    """argparse type: comma-separated finite numbers, at least one."""
    values = [_number(float, x, "a number") for x in csv_list(text)]
    if not values:
        raise argparse.ArgumentTypeError("give at least one number (comma separated)")
    bad = [x for x in values if not math.isfinite(x)]
    if bad:
        raise argparse.ArgumentTypeError(f"numbers must be finite, got {bad[0]}")
    return values


def _number(kind: Callable[[str], Any], text: str, what: str) -> Any:
    try:
        return kind(text.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text.strip()[:40]!r} is not {what}") from None


def print_json(result: Mapping[str, Any]) -> None:
    print(json.dumps(to_jsonable(result), allow_nan=False))


@contextmanager
def progress_bar(enabled: bool, total: float, min_interval: float = 0.1) -> Iterator[Any]:
    """A ``progress(done, total)`` callback drawing a tqdm bar on stderr, or None.

    The simulator calls it after every step (tens of thousands per run), so the bar
    is refreshed at most every ``min_interval`` seconds.
    """
    if not enabled:
        yield None
        return
    from tqdm import tqdm

    bar = tqdm(
        total=total,
        file=sys.stderr,
        desc="depositing",
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.1f}/{total:.0f} L_vb "
        "[{elapsed}<{remaining}]",
    )
    last = -math.inf

    def update(done: float, total: float) -> None:
        nonlocal last
        now = time.monotonic()
        if now - last >= min_interval or done >= total:
            bar.n = done
            bar.refresh()
            last = now

    try:
        yield update
    finally:
        bar.close()


ProgressCallback = Callable[[float, float], None]


# --------------------------------------------------------------------------- flags


def add_group_arguments(g: Any) -> None:
    """The dimensionless-group flags shared by ``run`` and ``sweep`` (runs.GROUP_FIELDS)."""
    g.add_argument("--Hbar", type=float, help="rod height H / L_vb")
    g.add_argument("--Ibar", type=float, help="mass per length rho e_v^2 / (k_b mu^2)")
    g.add_argument("--vbar", type=float, help="flow speed v mu H / e_v (>= 0)")
    g.add_argument("--phi", type=float, help="flow direction in the x-z plane from +x [rad]")
    g.add_argument(
        "--kappa-c",
        dest="kappa_c",
        type=float,
        help="critical curvature kappa_c L_vb (stepped substrate)",
    )
    g.add_argument(
        "--delta",
        type=float,
        help="discretisation length delta / L_vb (default: the preset's mesh, presets.MESH: "
        f"delta = {MESH['serpentine']['delta_bar']:g} on both presets; 1 with "
        "--drag-law printed is the fast surrogate, presets.SURROGATE)",
    )
    g.add_argument(
        "--dt",
        type=float,
        help="time step in mu L_vb^2 / e_v (default: DepositionConfig.dt_factor Hbar)",
    )


def add_model_arguments(m: Any) -> None:
    """The model and solver flags shared by ``run`` and ``sweep`` (see runs.resolve)."""
    m.add_argument(
        "--drag-law",
        choices=DRAG_LAWS,
        default=MODEL["drag_law"],
        help=f"drag law (default: {MODEL['drag_law']}; printed: the paper's eq. 2 as printed)",
    )
    m.add_argument(
        "--sliding",
        choices=SLIDING_OPTIONS,
        default=MODEL["sliding"],
        help="stepped substrate: B fixed in x, C free in x until snapped, none fixed in x "
        f"and z (default: {MODEL['sliding']})",
    )
    m.add_argument(
        "--friction",
        type=float,
        default=MODEL["friction"],
        metavar="ETA",
        help="stepped substrate: viscous friction on each sliding DOF of a deposited node, "
        f"-ETA l u, ETA in units of mu (default: {MODEL['friction']:g}; docs/model.md §4)",
    )
    m.add_argument(
        "--flow-profile",
        choices=FLOW_PROFILES,
        default=MODEL["flow_profile"],
        help="the flow over the height y: uniform (the paper's) or linear, a boundary layer "
        f"vbar y / Hbar with vbar at the rod's top (default: {MODEL['flow_profile']}; "
        "docs/model.md §4)",
    )
    m.add_argument(
        "--coarse-delta",
        type=float,
        default=None,
        help="graded mesh: inject edges of this length, split near the contact; 0 for a "
        f"uniform rod (default: {MESH['serpentine']['coarse_delta']:g}, snapped to a "
        "whole multiple of --delta)",
    )
    m.add_argument(
        "--fine-length",
        type=float,
        default=None,
        help="graded mesh: arc length above the contact kept at --delta (default: "
        f"{MESH['serpentine']['fine_length']:g})",
    )
    m.add_argument(
        "--contact-mode",
        choices=CONTACT_MODES,
        default="event",
        help="touchdown: event (the step that lands a node is cut to land it on y = 0) or "
        "project (the node is projected onto y = 0 after the step) (default: event)",
    )
    m.add_argument(
        "--adhesion",
        choices=ADHESION_MODELS,
        default=None,
        help="vdW adhesion: eq1, the paper's pull on the contact node, or cohesive, a pull "
        "of finite range on every free node near the substrate (default: eq1; "
        "docs/model.md §4)",
    )
    m.add_argument(
        "--cohesive-range",
        type=float,
        default=None,
        metavar="H",
        help="range of the cohesive adhesion, L_vb (default: 0.05)",
    )
    m.add_argument(
        "--initial-radius",
        type=float,
        metavar="R",
        help="radius of the start-up contact arc, L_vb (default: 6.4 flat, 3.9 stepped)",
    )


def add_settled_argument(g: Any) -> None:
    """``--settled-fraction``, shared by ``run``, ``measure`` and ``sweep``."""
    g.add_argument(
        "--settled-fraction",
        type=float,
        metavar="F",
        help="the last fraction of the U-turns on which periodic, irregular and "
        "serpentine-coil are judged, in (0, 1] (default: the run's, else "
        f"{SETTLED_FRACTION:g}; 1 judges the whole measured trace)",
    )


def add_limit_arguments(g: Any) -> None:
    """The named limits of a run (runs.Limits), shared by ``run`` and ``sweep``."""
    d = Limits()
    g.add_argument(
        "--max-nodes",
        type=int,
        default=d.max_nodes,
        metavar="N",
        help=f"nodes in a simulation, start-up rod plus trace (default {d.max_nodes})",
    )
    g.add_argument(
        "--max-steps",
        type=int,
        default=d.max_steps_per_length,
        metavar="N",
        help="physics steps allowed while less than 1 L_vb is deposited "
        f"(default {d.max_steps_per_length})",
    )
    g.add_argument(
        "--max-wall-time",
        type=float,
        default=d.max_wall_time,
        metavar="S",
        help=f"wall time of one run in seconds (default {d.max_wall_time:g}, a day)",
    )
