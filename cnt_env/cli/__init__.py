"""The ``cnt-sim`` command line (docs/cli.md): argparse and formatting only, thin over
:mod:`cnt_env.runs`, :mod:`cnt_env.sweep` and :mod:`cnt_env.replay`.

* :mod:`cnt_env.cli.common`: the error contract, the exit-code table, shared flags;
* :mod:`cnt_env.cli.run`: ``run``, ``measure``, ``demo``;
* :mod:`cnt_env.cli.sweep`: ``sweep``;
* :mod:`cnt_env.cli.app`: the parser, ``replay`` and ``main(argv=None)``.

The names below are re-exported for ``from cnt_env import cli`` users.
"""

from cnt_env.cli.app import build_parser, main
from cnt_env.cli.common import (
    EXIT_CODES,
    EXIT_FAILED,
    EXIT_INTERNAL,
    EXIT_INTERRUPTED,
    EXIT_LIMIT,
    EXIT_OK,
    EXIT_USAGE,
    PROG,
    CliError,
    package_version,
    progress_bar,
)
from cnt_env.cli.run import format_summary
from cnt_env.presets import DEFAULT_KAPPA_C
from cnt_env.runs import (
    GROUP_FIELDS,
    SI_FIELDS,
    RunSpec,
    apply_substrate,
    resolve_params,
    result_dict,
)

__all__ = [
    "DEFAULT_KAPPA_C",
    "EXIT_CODES",
    "EXIT_FAILED",
    "EXIT_INTERNAL",
    "EXIT_INTERRUPTED",
    "EXIT_LIMIT",
    "EXIT_OK",
    "EXIT_USAGE",
    "GROUP_FIELDS",
    "PROG",
    "SI_FIELDS",
    "CliError",
    "RunSpec",
    "apply_substrate",
    "build_parser",
    "format_summary",
    "main",
    "package_version",
    "progress_bar",
    "resolve_params",
    "result_dict",
]
