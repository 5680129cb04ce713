"""The ``cnt-sim`` command line: ``main(argv=None)``, the parser, and ``replay``.

``main`` is the console-script entry point (also ``python -m cnt_env``) and returns the
exit code from the one table in :mod:`cnt_env.cli.common` (docs/cli.md). Every error is
one line ``cnt-sim: error: <message>`` naming the flag or file; never a traceback.

* ``cnt-sim run``, ``measure``, ``demo``: :mod:`cnt_env.cli.run` over :mod:`cnt_env.runs`.
* ``cnt-sim sweep``: :mod:`cnt_env.cli.sweep` over :mod:`cnt_env.sweep`.
* ``cnt-sim replay FILE --rrd OUT.rrd``: a saved trace or episode as a rerun recording
  (:mod:`cnt_env.replay`; rerun is an optional extra).

The simulator and matplotlib are imported only by the commands that need them, so
``cnt-sim --version`` and argument errors are instant.
"""

from __future__ import annotations

import argparse
import difflib
import os
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

from cnt_env import units
from cnt_env.cli import sweep as sweep_cli
from cnt_env.cli.common import (
    EXIT_FAILED,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_LIMIT,
    EXIT_OK,
    EXIT_USAGE,
    PROG,
    CliError,
    add_settled_argument,
    double_dash_option,
    package_version,
    print_json,
    require_rerun,
)
from cnt_env.cli.run import add_run_arguments, cmd_measure, cmd_run, load_run_config
from cnt_env.io import OutputError, OutputSet, TraceFileError, load_trace
from cnt_env.presets import DEMO_DEPOSIT
from cnt_env.runs import RunInputError, RunLimitError

__all__ = ["build_parser", "main"]


def cmd_replay(args: argparse.Namespace) -> int:
    """A saved trace or episode as a rerun recording and/or a video (the kind from its
    ``format``)."""
    from cnt_env import replay
    from cnt_env.io import TRACE_FORMAT

    if args.rrd is None and args.video is None:
        raise CliError("give --rrd OUT.rrd, --video OUT.mp4 (or .gif), or both")
    outputs = OutputSet(inputs={"the file replayed": args.file})
    rrd = video = None
    if args.rrd is not None:
        rrd = outputs.check(args.rrd, "--rrd")
        outputs.check(f"{rrd}.json", "--rrd")
        require_rerun()
    if args.video is not None:
        video = outputs.check(args.video, "--video")
        if video.suffix.lower() not in replay.VIDEO_FORMATS:
            raise CliError(f"--video {video}: the name must end in one of "
                           f"{', '.join(replay.VIDEO_FORMATS)}")  # fmt: skip
        try:
            replay.import_imageio()
        except ImportError as exc:
            raise CliError(f"--video: {exc}", EXIT_FAILED) from exc
    try:
        kind = replay.file_format(args.file)
    except replay.EpisodeFileError as exc:
        raise CliError(str(exc)) from exc
    if kind not in (replay.EPISODE_FORMAT, TRACE_FORMAT):
        raise CliError(
            f"{args.file} is neither a cnt_env trace (`cnt-sim run --out`) nor a "
            f"cnt_env episode file (format {str(kind)[:80]!r})"
        )
    rid = None
    try:
        with outputs:
            source = args.file if kind == replay.EPISODE_FORMAT else load_trace(args.file)
            if rrd is not None:
                tmp = outputs.add(rrd, "--rrd", checked=True)
                if kind == replay.EPISODE_FORMAT:
                    rid = replay.record_episode(source, tmp, recording_id=args.recording_id)
                else:
                    rid = replay.record_simulation(source, tmp, recording_id=args.recording_id)
            if video is not None:
                replay.write_video(source, outputs.add(video, "--video", checked=True))
    except (TraceFileError, replay.EpisodeFileError) as exc:
        raise CliError(str(exc)) from exc
    except OSError as exc:
        raise CliError(f"cannot write {rrd or video}: {exc}", EXIT_FAILED) from exc
    result = {"file": str(args.file), "kind": kind, "rrd": None if rrd is None else str(rrd),
              "recording_id": rid, "video": None if video is None else str(video)}  # fmt: skip
    if args.json:
        print_json(result)
    else:
        if rrd is not None:
            print(f"wrote {rrd} (recording {rid}, from the {kind} file {args.file}); "
                  f"open it with `rerun {rrd}`")  # fmt: skip
        if video is not None:
            print(f"wrote {video} (from the {kind} file {args.file})")
    return EXIT_OK


def cmd_demo(args: argparse.Namespace) -> int:
    """A quick look (``make demo`` is the main job): a coil deposition with a figure,
    measured over its second half (the coil preset drops 900 L_vb, the paper's start-up,
    which a short demo never got past: its trace was not measured)."""
    outdir = Path(args.outdir)
    print(f"{PROG} {package_version()}: demo, {args.deposit:g} L_vb of coil deposition")
    run_argv = ["run", "--preset", "coil", "--deposit", repr(args.deposit),
                "--transient", repr(args.deposit / 2.0),
                "--out", str(outdir / "coil.npz"), "--png", str(outdir / "coil.png")]  # fmt: skip
    return main(run_argv)


class OneLineParser(argparse.ArgumentParser):
    """argparse's usage errors as the one line of docs/cli.md, ``cnt-sim: error: ...``
    (argparse printed the usage first), with the closest flag for an unknown one."""

    def error(self, message: str) -> NoReturn:
        if message.startswith("unrecognized arguments:"):
            flags = {f for p in _parsers(self) for a in p._actions for f in a.option_strings}
            unknown = [w for w in message.split(":", 1)[1].split() if w.startswith("-")]
            close = [m for w in unknown for m in difflib.get_close_matches(w, flags, n=1)]
            if close:
                message += f" (did you mean {', '.join(close)}?)"
        self.exit(EXIT_USAGE, f"{PROG}: error: {message}; see `{self.prog} --help`\n")


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommands' parsers by name."""
    subs = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return {name: p for s in subs for name, p in s.choices.items()}


def _parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """``parser`` and its subcommands' parsers."""
    return [parser, *_subcommands(parser).values()]


def _run_actions(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """The ``run`` subcommand's flags' actions by dest."""
    return {a.dest: a for a in _subcommands(parser)["run"]._actions if a.option_strings}


def _file_only_flags(
    actions: Mapping[str, argparse.Action], settings: Mapping[str, Any], argv: Sequence[str]
) -> dict[str, str]:
    """The flags a ``--config`` file sets and the command line does not, with their
    values: an error about one of them must name the file, where the user can fix it."""
    given = {w.split("=", 1)[0] for w in argv if w.startswith("--")}
    out: dict[str, str] = {}
    for dest, value in settings.items():
        flags = actions[dest].option_strings if dest in actions else []
        if flags and not given.intersection(flags):
            out[flags[-1]] = repr(value)
    return out


def _check_file_values(
    actions: Mapping[str, argparse.Action], settings: Mapping[str, Any], path: str
) -> None:
    """argparse neither checks the choices of a default nor names where a bad one came
    from: check the file's values as the flags' own types and choices would."""
    for dest, value in settings.items():
        action = actions.get(dest)
        if action is None:
            continue
        flag = action.option_strings[-1]
        try:
            typed = action.type(value) if callable(action.type) else value
        except (TypeError, ValueError, argparse.ArgumentTypeError):
            raise CliError(f"--config {path}: {flag} {value!r} is not a valid value") from None
        if action.choices is not None and typed not in action.choices:
            raise CliError(f"--config {path}: {flag} must be one of "
                           f"{', '.join(map(str, action.choices))}, got {value!r}")  # fmt: skip


def _name_the_file(message: str, from_file: Mapping[str, str], args: Any) -> str:
    """``message`` with the ``--config`` file named when it is about a flag only the file
    set."""
    named = [f for f in from_file if re.search(rf"{re.escape(f)}(?![\w-])", message)]
    if not named:
        return message
    values = ", ".join(f"{f} {from_file[f]}" for f in named)
    return f"{message.rstrip('.')} (set in --config {args.config}: {values})"


def build_parser(run_defaults: Mapping[str, Any] | None = None) -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog=PROG,
        description="Carbon-nanotube deposition simulator (discrete elastic rods).",
    )
    parser.add_argument("--version", action="version", version=f"{PROG} {package_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = sub.add_parser(
        "run",
        help="run one deposition",
        allow_abbrev=False,
        description="Run one deposition and measure its trace.",
    )
    add_run_arguments(run)
    run.set_defaults(func=cmd_run, **dict(run_defaults or {}))

    measure = sub.add_parser(
        "measure",
        help="measure a saved trace",
        allow_abbrev=False,
        description="Measure a trace saved by `cnt-sim run --out`.",
    )
    measure.add_argument("trace", help="trace file (.npz) written by `cnt-sim run --out`")
    measure.add_argument(
        "--transient",
        type=float,
        metavar="L",
        help="start-up arc length dropped, L_vb (default: the run's)",
    )
    add_settled_argument(measure)
    measure.add_argument("--png", metavar="FIG.png", help="plot the trace")
    measure.add_argument(
        "--json", action="store_true", help="print one JSON object on stdout and nothing else"
    )
    measure.set_defaults(func=cmd_measure)

    replay = sub.add_parser(
        "replay",
        help="turn a saved trace or episode into a rerun recording or a video",
        allow_abbrev=False,
        description="Write a rerun recording (.rrd) and/or a video (.mp4 or .gif) of a trace "
        "saved by `cnt-sim run --out` or of an episode saved by cnt_env.replay.save_episode; "
        'open a recording with `rerun FILE.rrd`. Needs the rerun extra (pip install -e ".[rerun]") '
        'for --rrd and the video extra (pip install -e ".[video]") for --video.',
    )
    replay.add_argument("file", help="trace.npz or episode.npz (told apart by their format)")
    replay.add_argument("--rrd", metavar="OUT.rrd", help="recording to write")
    replay.add_argument("--video", metavar="OUT.mp4", help="video to write (.mp4 or .gif)")
    replay.add_argument("--recording-id", default=None, help="default: the file's own")
    replay.add_argument(
        "--json", action="store_true", help="print one JSON object on stdout and nothing else"
    )
    replay.set_defaults(func=cmd_replay)

    demo = sub.add_parser("demo", help="a quick look: a short coil deposition, measured")
    demo.add_argument(
        "--deposit",
        type=float,
        default=DEMO_DEPOSIT,
        metavar="LENGTH",
        help=f"trace length, L_vb (default {DEMO_DEPOSIT:g})",
    )
    demo.add_argument("--outdir", default="runs/demo", help="output directory (runs/demo)")
    demo.set_defaults(func=cmd_demo)

    sweep_cli.add_parser(sub)
    return parser


def _one_line(message: str) -> str:
    """The message with every control character (newline, tab, ...; a file's entry names
    can hold them) written as an escape, so that an error stays on one line."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)


def _error(message: str, code: int) -> int:
    print(f"{PROG}: error: {_one_line(message)}", file=sys.stderr)
    return code


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cnt-sim``; returns the process exit code (argparse's too)."""
    parser = build_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, usage errors
        return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    from_file: dict[str, str] = {}  # flag -> the --config value it got (not overridden)
    if getattr(args, "config", None):  # cnt-sim run --config: the file's values, then flags
        try:
            settings = load_run_config(args.config)
            actions = _run_actions(parser)
            from_file = _file_only_flags(actions, settings, argv)
            _check_file_values(actions, settings, args.config)
            parser = build_parser(settings)
            args = parser.parse_args(argv)
        except CliError as exc:
            return _error(str(exc), exc.code)
        except SystemExit as exc:
            return exc.code if isinstance(exc.code, int) else EXIT_USAGE
    flag = double_dash_option(parser, args, argv)  # "--opt=--": a usage error, not a crash
    if flag is not None:
        return _error(f"{flag} got '--' as its value; give the value itself", EXIT_USAGE)
    args.argv = argv
    from cnt_env.sim.stepper import SimulationError
    from cnt_env.sweep import SweepFailure

    try:
        return int(args.func(args))
    except CliError as exc:
        return _error(str(exc), exc.code)
    except (RunInputError, OutputError, TraceFileError, units.ParameterError) as exc:
        return _error(_name_the_file(str(exc), from_file, args), EXIT_USAGE)
    except RunLimitError as exc:
        return _error(str(exc), EXIT_LIMIT)
    except (SimulationError, SweepFailure) as exc:
        return _error(str(exc), EXIT_FAILED)
    except OSError as exc:
        where = f" {exc.filename}" if exc.filename else ""
        return _error(f"cannot read or write{where}: {exc.strerror or exc}", EXIT_FAILED)
    except MemoryError:
        return _error("out of memory; lower --max-nodes or --deposit", EXIT_FAILED)
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:
        if os.environ.get("CNT_SIM_TRACEBACK") == "1":
            raise
        text = " ".join(str(exc).split())[:300]
        return _error(f"unexpected {type(exc).__name__}: {text} (a bug: please report it, "
                      "with CNT_SIM_TRACEBACK=1 for the traceback)", EXIT_INTERNAL)  # fmt: skip


if __name__ == "__main__":
    raise SystemExit(main())
