"""The ``cnt-sim`` command line: thin subcommands over importable functions.

Each subcommand parses its arguments and calls one function of this package;
``main(argv=None)`` is the console-script entry point.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _dist_version

DIST_NAME = "cnt-env"
PROG = "cnt-sim"


def package_version() -> str:
    """The installed distribution's version, or the source tree's when not installed."""
    try:
        return _dist_version(DIST_NAME)
    except PackageNotFoundError:
        from cnt_env import __version__

        return __version__


def run_demo(args: argparse.Namespace) -> int:
    """The main job (``make demo``). Placeholder until the simulation core is wired."""
    print(f"{PROG} {package_version()}")
    print("demo: simulation core not wired yet")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description="Carbon-nanotube deposition simulator (discrete elastic rods).",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    demo = sub.add_parser("demo", help="run the main job: a small deposition")
    demo.set_defaults(func=run_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cnt-sim``; returns the process exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    raise SystemExit(main())
