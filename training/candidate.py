"""A trained residual agent as a candidate: its network over another agent's base and gate.

    python -m training.candidate RUN/ppo.zip --like policies/pretrained/ppo_residual.yml \\
        --name ms_final --out MODELS [--mirror-average] [--keepout-headings=-z,+z] \\
        [--note "..."]

A residual agent's ``.yml`` (written by cnt-train beside its zip) says how it acts: its
``env_wrapper`` entry ``training.common.ResidualAction`` holds the base follower's
options, the gate (``keepout_headings``) and ``mirror_average``. Candidates for shipping
are judged as the shipped agent is evaluated, over its base and gate
(``policies/pretrained/ppo_residual.yml``), which may differ from the ones the run trained
over (e.g. options added to the base after training). This copies the model's zip and
VecNormalize statistics to ``<out>/<name>*``, writes ``<out>/<name>.yml`` = the run's
config with ``--like``'s ResidualAction entry, plus the options given here, and notes
under ``run: base_set_after_training`` what was set; then it rewrites ``<out>``'s
``MANIFEST.json``. The network, its normalisation and every other setting stay the run's.

Before 2026-12-06 each run's ``drive.sh`` did this with its own inline script
(``route_runs/mirror_hour``, ``mirror_stage1``, ``mirror_symgate``); this module
rebuilds their model configs to the byte (``tests/test_training.py``).
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path
from typing import Any

import yaml

from policies.opening import AXES
from policies.residual import WRAPPER, zoo_entry
from policies.sb3 import model_files, write_manifest

from .common import ENV_ID, parse_cli

__all__ = ["candidate_config", "main", "make_candidate"]


def _residual_entry(config: dict[str, Any], source: str) -> list[dict[str, Any]]:
    """The ``env_wrapper`` list of ``config`` whose first item is the ResidualAction."""
    wrappers = config.get(ENV_ID, {}).get("env_wrapper")
    if not isinstance(wrappers, list) or zoo_entry(wrappers[:1], WRAPPER) is None:
        raise ValueError(f"{source} is not a residual agent's config: its {ENV_ID} "
                         f"env_wrapper does not start with {WRAPPER}")  # fmt: skip
    return wrappers


def candidate_config(run: dict[str, Any], like: dict[str, Any], note: str,
                     mirror_average: bool = False,
                     keepout_headings: list[str] | None = None) -> str:  # fmt: skip
    """The YAML text of a candidate: ``run`` (a whole rl-zoo file, parsed) with the
    ResidualAction options of ``like``, then ``keepout_headings`` (if given) and
    ``mirror_average: true`` (if set) over them, and ``note`` as
    ``run: base_set_after_training``."""
    wrappers = _residual_entry(run, "the run's config")
    wrap = zoo_entry(_residual_entry(like, "--like")[:1], WRAPPER)
    if keepout_headings is not None:
        wrap["keepout_headings"] = list(keepout_headings)
    if mirror_average:
        wrap["mirror_average"] = True
    wrappers[0][WRAPPER] = wrap
    run.setdefault("run", {})["base_set_after_training"] = note
    return yaml.safe_dump(run, sort_keys=False)


def make_candidate(model: Path, like: Path, name: str, out: Path, note: str | None = None,
                   mirror_average: bool = False,
                   keepout_headings: list[str] | None = None) -> Path:  # fmt: skip
    """Write the candidate ``<out>/<name>.zip`` (+ statistics and ``.yml``) and the
    folder's manifest; returns the zip's path."""
    zip_path, npz, js, _pkl, yml = model_files(model)
    missing = [p for p in (zip_path, npz, js, yml) if not p.is_file()]
    if missing:
        raise ValueError(f"{model} lacks {', '.join(map(str, missing))}: give a model that "
                         "cnt-train saved (its zip, VecNormalize .npz/.json and .yml)")  # fmt: skip
    run = yaml.safe_load(yml.read_text())
    like_cfg = yaml.safe_load(Path(like).read_text())
    if note is None:
        note = f"the base of {like}"
        if keepout_headings is not None:
            note += f", gate [{', '.join(keepout_headings)}]"
    text = candidate_config(run, like_cfg, note, mirror_average, keepout_headings)
    out.mkdir(parents=True, exist_ok=True)
    target, target_npz, target_js, _, target_yml = model_files(out / f"{name}.zip")
    for src, dst in ((zip_path, target), (npz, target_npz), (js, target_js)):
        shutil.copyfile(src, dst)
    target_yml.write_text(text)
    write_manifest(out)
    return target


def _headings(text: str) -> list[str]:
    items = [h.strip() for h in text.split(",") if h.strip()]
    bad = [h for h in items if h not in AXES]
    if bad:
        raise argparse.ArgumentTypeError(f"headings are {', '.join(AXES)}; got {bad}")
    return items


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m training.candidate",
                                description=__doc__.splitlines()[0])  # fmt: skip
    p.add_argument("model", type=Path, help="a residual agent's zip saved by cnt-train")
    p.add_argument("--like", type=Path, required=True,
                   help="the agent whose base and gate the candidate takes (its .yml)")  # fmt: skip
    p.add_argument("--name", required=True, help="the candidate's name (its file stem)")
    p.add_argument("--out", type=Path, required=True, help="the models folder")
    p.add_argument("--mirror-average", action="store_true",
                   help="average the action with the mirrored observation's (z -> -z)")  # fmt: skip
    p.add_argument("--keepout-headings", type=_headings, default=None,
                   help="the gate, e.g. -z,+z (default: --like's); '' for none")  # fmt: skip
    p.add_argument("--note", default=None, help="run: base_set_after_training")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parse_cli(parser, argv)
    if not args.name or "/" in args.name or args.name.endswith(".zip"):
        parser.error(f"--name must be a bare file stem, got {args.name!r}")
    try:
        path = make_candidate(args.model.with_suffix(".zip"), args.like, args.name, args.out,
                              args.note, args.mirror_average, args.keepout_headings)  # fmt: skip
    except (ValueError, OSError, yaml.YAMLError) as exc:
        parser.error(str(exc))
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
