"""Evaluate every policy on the held-out targets (``cnt-evaluate``).

    cnt-evaluate [--policies random,constant,scripted,ppo,sac] [--targets all]
                 [--route-file FILE]
                 [--seeds 0,1,2] [--models policies/pretrained ...] [--runs DIR ...]
                 [--config training/configs/eval.yml] [--constant-from FILE]
                 [--out training/results] [--jobs 2] [--save-episodes DIR] [--rrd DIR]
                 [--video DIR [--video-format mp4|gif]] [--trust]
                 [--reuse DIR ... [--redo POLICIES]]

For every (policy, held-out target, seed) it runs one episode of CNTDeposit-v0 (the
targets may also be routes of your own, ``--route-file``: docs/task.md) with the
env settings of ``--config`` (by default ``eval.yml``: the env's default physics, the
model; a training config gives the fast surrogate the agents were trained on) and
writes, in ``--out``:

* ``episodes.csv``: one row per episode (final score Φ, its terms, mean distance,
  length laid, steps, success, failure, wall time; success is ``info["is_success"]``:
  the route completed with every pad met and no short, docs/task.md; routes also give
  ``short_length``, ``pads_crossed`` and ``n_pads``, empty in rows reused from runs
  before 2026-12-07);
* ``results.csv``: per policy and target, and over all targets (``target = ALL``):
  mean ± std over seeds of the score and its terms, the success rate, and the normalised score
  (score - random) / (1 - random) (best possible score = 1). The ``ALL`` row takes,
  per seed, the mean over targets, then mean ± std over seeds;
* ``results.md``: the same as Markdown tables (for the README);
* ``summary.json``: ``{"policies": {name: {"score_mean", "score_std"}}, "targets",
  "seeds", "custom_routes", "env_kwargs", "max_episode_steps", "models",
  "model_sha256"}`` (the ``ALL`` rows; the routes evaluated from ``--route-file``, in the
  dict format; the physics, the trained models and their files' sha256, which
  ``--reuse`` checks: a trained policy's episodes are reused only from a run of the same
  model file);
* ``constant_grid.csv`` and ``constant_best.json``: the constant-flow grid search
  (policies/constant.py), unless ``--constant-from`` gives a previous ``constant_best.json``;
* ``traces_<target>.png`` (and ``traces.png``, all targets): the trace laid by each
  policy (first seed) over the target; ``learning_curves.png`` from the run directories'
  ``evaluations.npz`` (``--runs``).

An ``--out`` used before keeps the files this evaluation does not write (a ``--reuse``
re-run keeps ``learning_curves.png`` so); they are listed at the end.

``--save-episodes DIR`` saves every episode with :class:`cnt_env.replay.EpisodeSaver`
(``cnt_env.episode`` npz files, ``<policy>-<target>-s<seed>-e0000.npz``; the recordings
and videos below take the same name); ``--rrd DIR`` also writes a rerun recording of each
policy's first-seed episode per target (skipped with a message if rerun is missing);
``--video DIR`` writes an MP4 (``--video-format gif``: a GIF) of every episode
(:func:`cnt_env.replay.write_video`; needs the video extra).

A policy ``a+b`` is the ensemble of models ``a`` and ``b``: it plays the mean of their
actions (:class:`policies.ensemble.MeanPolicy`); ``a|b`` plays model a on routes without
a keep-out and b on routes with one (:class:`policies.ensemble.KeepoutSplit`; quote it in
a shell); ``--models`` may list several directories, the first holding a name wins.

Models are loaded without running code from their files (:func:`policies.load_policy`,
docs/security.md); ``--trust`` lifts that for files you trust.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import multiprocessing as mp
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cnt_env.io import to_jsonable
from cnt_env.task import routes
from policies.residual import residual_settings
from policies.sb3 import frame_stack

from .common import (
    ENV_ID,
    EVAL_CONFIG,
    VALIDATION,
    DefaultsHelp,
    HeldOutCycle,
    check_dir_option,
    csv_list,
    env_settings,
    eval_env_settings,
    eval_settings,
    fresh_dir,
    held_out_names,
    held_out_targets,
    limit_threads,
    load_config,
    make_env,
    observation_mode,
    parse_cli,
    positive_int,
    score_mode,
    seed_list,
    shown_path,
)

__all__ = ["ALL_POLICIES", "evaluate", "main"]

ALL_POLICIES = ("random", "constant", "scripted", "ppo", "sac")
#: Policies that need no model; any other name is a model ``<models>/<name>.zip`` whose
#: name contains its algorithm (ppo.zip, sac.zip, ppo_residual.zip) or whose config beside
#: it (``<name>.yml``, ``run: algo:``) names it.
BASELINES = ("random", "constant", "scripted")
TERMS = ("score", "coverage", "precision", "progress", "mean_distance")
#: Grid of the constant-flow search: speeds (e_v / (mu H)) and number of directions. The
#: paper's baseline speed and the three of the route task's step response (band 34-51
#: L_vb peak to peak at 0.13-0.065, benchmarks/results/step_response_surrogate.json), so that the
#: oracle has every band width that could fit a corridor.
CONSTANT_SPEEDS = (0.037, 0.065, 0.1, 0.13)
CONSTANT_DIRECTIONS = 8
#: Seeds of the constant-flow search, apart from the evaluation seeds.
CONSTANT_SEARCH_SEEDS = (100,)
PRETRAINED = Path(__file__).resolve().parents[1] / "policies" / "pretrained"
COLORS = {"random": "0.6", "constant": "tab:orange", "scripted": "tab:green",
          "ppo": "tab:blue", "sac": "tab:purple", "ppo_residual": "tab:cyan",
          "ppo_long": "tab:red"}  # fmt: skip
#: Colours for a further run of a policy already drawn in a panel (none of the baselines').
EXTRA_COLORS = ("tab:red", "tab:brown", "tab:pink", "tab:olive", "tab:gray", "tab:purple")
#: The env's keywords that set only what a policy observes (not the physics, the task or
#: the score): a trained model is evaluated with its own, from the config beside it, so
#: that an image agent and the vector baselines play the same episodes.
OBSERVATION_KEYS = (
    "obs_mode", "image_size", "image_extent", "image_layers",
    "n_trace_points", "n_target_points", "trace_window", "target_spacing",
)  # fmt: skip


def observation_settings(models: Sequence[Path]) -> dict[str, Any]:
    """The observation keywords (``OBSERVATION_KEYS``) the models were trained with, from
    the configs beside them (``<name>.yml``; none for a model without one). ValueError if
    the members of an ensemble observe differently."""
    from policies.sb3 import model_config

    seen = []
    for m in models:
        cfg = model_config(Path(m))
        entry = cfg.get(ENV_ID) if isinstance(cfg, dict) else None
        kw = env_settings(entry)[0] if isinstance(entry, dict) else {}
        seen.append({k: kw[k] for k in OBSERVATION_KEYS if k in kw})
    if any(o != seen[0] for o in seen[1:]):
        raise ValueError(f"the models {[str(m) for m in models]} observe differently "
                         f"({seen}): an ensemble needs one observation")  # fmt: skip
    return seen[0] if seen else {}


def model_hashes(policy: str, models: Path | Sequence[Path],
                 model_paths: Mapping[str, Path] | None = None) -> list[str] | None:  # fmt: skip
    """The sha256 of each model file of a trained ``policy`` (its ensemble members), None
    where one is missing (a reused policy need not have its model here)."""
    from policies.sb3 import file_sha256

    paths = [model_file(n, models, model_paths) for n in ensemble_members(policy)]
    return [file_sha256(q) for q in paths] if all(q.is_file() for q in paths) else None


def _recorded_hashes(path: Path) -> dict[str, list[str]]:
    """The model sha256s a results directory's ``summary.json`` records ({} before they
    were recorded, 2026-12-07)."""
    summary = path / "summary.json"
    if not summary.is_file():
        return {}
    return dict(json.loads(summary.read_text()).get("model_sha256") or {})


# ---- one episode (runs in a worker process) ---------------------------------------------


def _make_policy(spec: dict[str, Any], env):
    from policies import ConstantPolicy, RandomPolicy, RouteFollower, ScriptedPolicy, load_policy

    kind = spec["kind"]
    if kind == "random":
        return RandomPolicy()
    if kind == "constant":
        return ConstantPolicy(spec["vbar"], spec["phi"], env.unwrapped.vbar_max)
    if kind == "scripted":  # the baseline of the env's task
        if env.unwrapped.score_mode == "corridor":
            return RouteFollower.from_env(env)
        return ScriptedPolicy.from_env(env)
    agents = [load_policy(m, trust=bool(spec.get("trust")), env=env) for m in spec["models"]]
    if len(agents) == 1:
        return agents[0]
    from policies.ensemble import KeepoutSplit, MeanPolicy

    if SPLIT in kind:
        return KeepoutSplit(*agents, env.unwrapped.observation_slices, name=kind)
    return MeanPolicy(agents, name=kind)


def model_file(name: str, models: Path | Sequence[Path],
               model_paths: Mapping[str, Path] | None = None) -> Path:  # fmt: skip
    """``model_paths[name]`` if given, else ``<dir>/<name>.zip`` in the first of the
    ``models`` directories that holds it (the first directory's path when none does, for
    the error)."""
    if (model_paths or {}).get(name):
        return Path(model_paths[name])
    dirs = [Path(models)] if isinstance(models, (str, Path)) else [Path(d) for d in models]
    paths = [d / f"{name}.zip" for d in dirs]
    return next((q for q in paths if q.is_file()), paths[0])


#: ``a|b``: model a on routes without a keep-out, b on routes with one
#: (:class:`policies.ensemble.KeepoutSplit`)
SPLIT = "|"


def ensemble_members(policy: str) -> list[str]:
    """The model names of a policy: ``a+b`` is the ensemble of models ``a`` and ``b``
    (:class:`policies.ensemble.MeanPolicy`), ``a|b`` model a on routes without a keep-out
    and b on routes with one (:class:`policies.ensemble.KeepoutSplit`), any other name
    one model."""
    if SPLIT in policy:
        members = policy.split(SPLIT)
        if len(members) != 2 or "+" in policy or not all(members):
            raise ValueError(f"a keep-out split is two model names, 'a|b', got {policy!r}")
        return members
    return policy.split("+")


def _play(env, policy, obs) -> tuple[int, float, dict[str, Any]]:
    """Step ``env`` with ``policy`` from ``obs`` to the episode's end: (steps, return,
    last info)."""
    steps, ret = 0, 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy.act(obs))
        steps += 1
        ret += float(reward)
        if terminated or truncated:
            return steps, ret, info


def episode_frame(base: Any) -> tuple[np.ndarray, np.ndarray]:
    """The episode's trace so far (the contact point at reset first) and its target
    polyline, both in the substrate plane (x, z) relative to that contact point: the frame
    of the results' plots and of ``benchmarks/outside_where.py``. ``base`` is the
    unwrapped env."""
    trace = base.sim.trace()
    origin = trace[base.episode_start - 1, [0, 2]]
    return trace[base.episode_start - 1 :, [0, 2]] - origin, base.target_path - origin


def run_episode(job: dict[str, Any]) -> dict[str, Any]:
    """One episode of ``job`` = {policy, spec, target, seed, env_kwargs, max_steps,
    save_dir}; returns the final metrics and the trace."""
    limit_threads()
    env = make_env(job["env_kwargs"], job["max_steps"])
    if job.get("save_dir"):
        from cnt_env.replay import EpisodeSaver

        env = EpisodeSaver(env, job["save_dir"], tag=f"{job['policy']}-{job['target']}")
    policy = _make_policy(job["spec"], env)
    t0 = time.perf_counter()
    # a route of --route-file travels as its dict; a held-out one by name
    obs, info = env.reset(seed=job["seed"], options={"target": job.get("route") or job["target"]})
    policy.reset(job["seed"])
    steps, ret, info = _play(env, policy, obs)
    base = env.unwrapped
    corridor = getattr(base.target, "width", None)  # route task: the corridor half-width
    trace, target = episode_frame(base)
    row = {
        "policy": job["policy"], "target": job["target"], "seed": job["seed"],
        **{k: float(info[k]) for k in TERMS}, "return": ret,
        "laid_length": float(info["laid_length"]), "target_length": float(info["target_length"]),
        "steps": steps, "is_success": bool(info["is_success"]),
        "failure": info.get("failure", ""), "wall_s": round(time.perf_counter() - t0, 2),
    }  # fmt: skip
    if corridor is not None:  # what is_success asks of a route, to audit it by
        row["short_length"] = float(info["short_length"])
        row["pads_crossed"], row["n_pads"] = int(info["pads_crossed"]), int(info["n_pads"])
    rec = getattr(env, "paths", None)
    env.close()
    return {
        "row": row,
        "trace": trace,
        "target_points": target,
        "corridor": None if corridor is None else float(corridor),
        "episode_file": str(rec[-1]) if rec else None,
    }


# ---- constant-flow grid search ------------------------------------------------------------


def _record_constant(args: tuple) -> Any:
    from policies.constant import record_constant

    limit_threads()
    env_kwargs, max_steps, vbar, phi, seed = args
    env = make_env(env_kwargs, max_steps)
    try:
        return record_constant(env, vbar, phi, seed, max_steps)
    finally:
        env.close()


def _mapped(pool: Any, fn: Any, jobs: list[dict[str, Any]], what: str) -> list[Any]:
    """``pool.map(fn, jobs)`` in order, with a progress bar on a terminal (an evaluation
    on the model runs for minutes; nothing is printed to a log or a pipe)."""
    it = pool.imap(fn, jobs, chunksize=1)
    if not (sys.stderr.isatty() and jobs):
        return list(it)
    from tqdm import tqdm

    return list(tqdm(it, total=len(jobs), desc=what, unit="run", file=sys.stderr))


def constant_search(
    env_kwargs, max_steps, targets, pool, out: Path,
    route_of: Mapping[str, routes.Route] | None = None,
) -> dict[str, dict]:  # fmt: skip
    """Best constant flow per target (policies/constant.py); writes the grid and the
    choice to ``out``. ``route_of``: the routes of the corridor task by name (default: the
    held-out routes)."""
    from policies.constant import grid, search

    env = make_env(env_kwargs, max_steps)
    base = env.unwrapped
    tol = base.tolerance
    weights = tuple(float(w) for w in base.weights)
    mode = base.score_mode
    limits = None
    if mode == "corridor":  # each route's own episode length (env.episode_steps_for)
        route_of = route_of or {t: routes.held_out(t) for t in targets}
        limits = {t: min(max_steps, base.episode_steps_for(route_of[t])) for t in targets}
        max_steps = max(limits.values())
    env.close()
    flows = grid(CONSTANT_SPEEDS, CONSTANT_DIRECTIONS)
    jobs = [(env_kwargs, max_steps, v, p, s) for v, p in flows for s in CONSTANT_SEARCH_SEEDS]
    traces = _mapped(pool, _record_constant, jobs, "constant flows")
    best, rows = search(traces, targets, tol, weights, score=mode, step_limits=limits,
                        route_of=route_of)  # fmt: skip
    _write_csv(out / "constant_grid.csv", rows)
    meta = {"speeds": CONSTANT_SPEEDS, "n_directions": CONSTANT_DIRECTIONS,
            "search_seeds": CONSTANT_SEARCH_SEEDS, "max_episode_steps": max_steps,
            "best": best}  # fmt: skip
    (out / "constant_best.json").write_text(json.dumps(meta, indent=2) + "\n")
    return best


# ---- tables -------------------------------------------------------------------------------


def _write_csv(path: Path, rows: Sequence[dict[str, Any]]) -> None:
    """``rows`` as CSV; the columns are every key in the order first seen (a row reused
    from an older run may lack a newer column: its cell is left empty)."""
    if not rows:
        return
    fields = list(dict.fromkeys(k for r in rows for k in r))
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def aggregate(rows: Sequence[dict[str, Any]], policies: Sequence[str], targets: Sequence[str],
              seeds: Sequence[int]) -> list[dict[str, Any]]:  # fmt: skip
    """Per (policy, target) and over all targets (per-seed means over targets), mean ±
    std over seeds, and the normalised score against random (module doc)."""
    by = defaultdict(dict)
    for r in rows:
        by[(r["policy"], r["target"])][r["seed"]] = r
    table = []
    rand = {}
    for t in targets:
        if ("random", t) in by:
            rand[t] = float(np.mean([x["score"] for x in by[("random", t)].values()]))

    def norm(score: float, floor: float | None) -> float:
        return (score - floor) / (1.0 - floor) if floor is not None else math.nan

    for p in policies:
        for t in targets:
            eps = list(by[(p, t)].values())
            if not eps:
                continue
            row = {"policy": p, "target": t, "n": len(eps)}
            for k in TERMS:
                v = [e[k] for e in eps]
                row[f"{k}_mean"], row[f"{k}_std"] = float(np.mean(v)), float(np.std(v))
            row["success_rate"] = float(np.mean([e["is_success"] for e in eps]))
            row["normalized_score"] = norm(row["score_mean"], rand.get(t))
            table.append(row)
        per_seed = {k: [] for k in TERMS}
        norm_seed = []
        for s in seeds:
            eps = [by[(p, t)][s] for t in targets if s in by[(p, t)]]
            if len(eps) != len(targets):
                continue
            for k in TERMS:
                per_seed[k].append(float(np.mean([e[k] for e in eps])))
            if len(rand) == len(targets):
                norm_seed.append(norm(per_seed["score"][-1], float(np.mean(list(rand.values())))))
        if per_seed["score"]:
            row = {"policy": p, "target": "ALL", "n": len(per_seed["score"]) * len(targets)}
            for k in TERMS:
                row[f"{k}_mean"] = float(np.mean(per_seed[k]))
                row[f"{k}_std"] = float(np.std(per_seed[k]))
            row["success_rate"] = float(np.mean([
                by[(p, t)][s]["is_success"] for t in targets for s in by[(p, t)]
            ]))  # fmt: skip
            row["normalized_score"] = float(np.mean(norm_seed)) if norm_seed else math.nan
            table.append(row)
    return table


def _save_results(out: Path, results: Sequence[dict[str, Any]]) -> None:
    """``episodes.json`` (rows) and ``traces.npz`` (trace and target per episode), for
    ``--reuse``."""
    rows = [r["row"] for r in results]
    (out / "episodes.json").write_text(json.dumps(rows) + "\n")
    arrays = {}
    for i, r in enumerate(results):
        arrays[f"trace_{i}"] = r["trace"].astype(np.float32)
        arrays[f"target_{i}"] = r["target_points"].astype(np.float32)
    np.savez_compressed(out / "traces.npz", **arrays)


def _episode_key(row: Mapping[str, Any]) -> tuple[str, str, int]:
    """An episode's (policy, target, seed)."""
    return row["policy"], row["target"], int(row["seed"])


def _load_results(
    path: Path, wanted: set[tuple[str, str, int]],
    custom: Mapping[str, routes.Route] | None = None,
) -> list[dict[str, Any]]:  # fmt: skip
    """Episodes saved by a previous run in ``path`` whose (policy, target, seed) is in
    ``wanted`` and whose target is the same route as now: a name of ``custom``
    (``--route-file``) only where that run recorded the same route for it, any other name
    only where it was not a route of a file there (its ``summary.json``'s
    ``custom_routes``). Only their traces are read."""
    rows = json.loads((path / "episodes.json").read_text())
    data = np.load(path / "traces.npz")
    summary = path / "summary.json"
    theirs = json.loads(summary.read_text()).get("custom_routes", {}) if summary.is_file() else {}
    ours = {t: json.loads(json.dumps(r.to_dict())) for t, r in (custom or {}).items()}
    return [{"row": row, "trace": data[f"trace_{i}"], "target_points": data[f"target_{i}"],
             "episode_file": None}
            for i, row in enumerate(rows) if _episode_key(row) in wanted
            and theirs.get(row["target"]) == ours.get(row["target"])]  # fmt: skip


# ---- plots --------------------------------------------------------------------------------


def plot_traces(results: Sequence[dict[str, Any]], targets: Sequence[str], out: Path,
                route_of: dict[str, Any] | None = None) -> None:  # fmt: skip
    """``traces_<target>.png`` and ``traces.png``: each policy's first-seed trace over the
    target; with ``route_of`` (target -> Route, the corridor task) the route's corridor,
    pads and keep-outs from the route itself (reused episodes do not carry them)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    first = {}
    for r in results:
        key = (r["row"]["policy"], r["row"]["target"])
        if key not in first or r["row"]["seed"] < first[key]["row"]["seed"]:
            first[key] = r
    policies = list(dict.fromkeys(r["row"]["policy"] for r in results))

    def draw(ax, t):
        from cnt_env.plotting import draw_route

        r0 = next(first[(p, t)] for p in policies if (p, t) in first)
        route = (route_of or {}).get(t)
        if route is not None:
            draw_route(ax, r0["target_points"], corridor=route.width, pads=route.pads,
                       keepouts=route.keepouts, pad_width=route.pad_width)  # fmt: skip
        else:
            draw_route(ax, r0["target_points"], corridor=r0.get("corridor"))
        for p in policies:
            if (p, t) in first:
                tr = first[(p, t)]["trace"]
                sc = first[(p, t)]["row"]["score"]
                ax.plot(tr[:, 0], tr[:, 1], color=COLORS.get(p), lw=1.0, label=f"{p} Φ={sc:.2f}")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(t)
        ax.set_xlabel("x (L_vb, across the steps)")
        ax.set_ylabel("z (L_vb)")

    for t in targets:
        fig, ax = plt.subplots(figsize=(6, 5))
        draw(ax, t)
        ax.legend(fontsize=7, loc="best")
        fig.tight_layout()
        fig.savefig(out / f"traces_{t}.png", dpi=90)
        plt.close(fig)
    n = len(targets)
    cols = min(4, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.8 * rows), squeeze=False)
    for ax, t in zip(axes.flat, targets, strict=False):
        draw(ax, t)
        ax.legend(fontsize=6, loc="best")
    for ax in list(axes.flat)[n:]:
        ax.set_axis_off()
    fig.tight_layout()
    fig.savefig(out / "traces.png", dpi=80)
    plt.close(fig)


#: Baselines drawn as lines on a learning curve (when evaluated on the curve's routes).
CURVE_BASELINES = ("constant", "scripted", "random")


def _run_info(run: Path) -> tuple[tuple[str, ...], int, str, str, dict[str, Any]]:
    """A run's EvalCallback routes, its eval episodes per evaluation, its policy name
    (``ppo``, ``sac``, ``ppo_residual``), a label with its seed, observation (when not the
    vector), sample count and wall time, and its config entry (from its config.yml; the
    directory name when absent)."""
    path = Path(run) / "config.yml"
    if not path.is_file():
        return (), 0, Path(run).name.rsplit("_s", 1)[0], Path(run).name, {}
    with path.open() as fh:
        data = yaml.safe_load(fh)
    cfg = data.get(ENV_ID, {}) if isinstance(data, dict) else {}
    ev = eval_settings(cfg)
    meta = data.get("run", {}) if isinstance(data, dict) else {}
    name = str(meta.get("algo", Path(run).name.rsplit("_s", 1)[0]))
    if residual_settings(cfg):
        name += "_residual"
    if (n_stack := frame_stack(cfg)) > 1:
        name += f"_stack{n_stack}"
    label = f"{name} s{meta.get('seed', '?')}"
    if (obs := observation_mode(cfg)) != "vector":
        label += f" [{obs}]"  # runs of one algorithm on other observations told apart
    if "timesteps_done" in meta and "wall_time_s" in meta:
        label += f" ({meta['timesteps_done']} steps, {meta['wall_time_s'] / 60:.0f} min)"
    return tuple(ev["eval_targets"]), ev["n_eval_episodes"], name, label, cfg


def _baselines_code() -> str:
    """A fingerprint of everything a no-model baseline's score depends on: its source
    (policies/base.py, scripted.py, route_follower.py), the task (cnt_env/task) and the
    simulator (the warm-start cache's source fingerprint). A cached score is stale when
    any of them changes (a cache keyed on the policies alone kept a follower's score from
    before a solver change)."""
    import hashlib

    import cnt_env.task
    import policies
    from cnt_env.sim.warmstart import source_fingerprint

    h = hashlib.sha256(source_fingerprint().encode())
    root = Path(policies.__file__).parent
    for name in ("base.py", "scripted.py", "route_follower.py"):
        h.update((root / name).read_bytes())
    for f in sorted(Path(cnt_env.task.__file__).parent.glob("*.py")):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def eval_set_baselines(run: Path, policies: Sequence[str] = ("scripted", "random"),
                       cache_dir: Path | None = None) -> dict:  # fmt: skip
    """Mean final score of the no-model ``policies`` on a run's EvalCallback episodes
    (the same routes and reset seeds, :class:`training.common.HeldOutCycle`), for runs
    evaluated on validation routes, which ``cnt-evaluate`` does not score otherwise.
    Cached in ``<run>/eval_baselines.json`` (recomputed if its routes or the baselines'
    code differ). With ``cache_dir`` a recomputed cache goes to
    ``<cache_dir>/eval_baselines_<run name>.json`` instead, and the run (perhaps a
    committed result) is only read."""
    run = Path(run)
    targets, n, _, _, cfg = _run_info(run)
    cache = run / "eval_baselines.json"
    mine = cache if cache_dir is None else Path(cache_dir) / f"eval_baselines_{run.name}.json"
    code = _baselines_code()
    for path in dict.fromkeys((cache, mine)):
        if not path.is_file():
            continue
        try:
            data = json.loads(path.read_text())
            if (data.get("eval_targets") == list(targets) and data.get("n") == n
                    and data.get("code") == code):  # fmt: skip
                return {p: float(data["scores"][p]) for p in policies}
        except (ValueError, KeyError, TypeError):
            pass  # rebuilt below
    env_kwargs, max_steps = eval_env_settings(cfg)
    # the baselines observe the vector: an image run's routes and physics, not its image
    env_kwargs = {k: v for k, v in env_kwargs.items() if k not in OBSERVATION_KEYS}
    scores = {}
    for p in policies:
        env = HeldOutCycle(make_env(env_kwargs, max_steps), targets)
        policy = _make_policy({"kind": p}, env)
        vals = []
        for i in range(n):
            obs, _ = env.reset()
            policy.reset(i)
            vals.append(float(_play(env, policy, obs)[2]["score"]))
        env.close()
        scores[p] = float(np.mean(vals))
    mine.write_text(json.dumps({"eval_targets": list(targets), "n": n, "code": code,
                                "scores": scores}) + "\n")  # fmt: skip
    return scores


def _env_label(cfg: dict[str, Any]) -> str:
    """The env a run's EvalCallback ran on (:func:`eval_env_settings`), in short: its
    physics (the env's default, the model, unless the config sets the drag law, delta_bar
    or a flow gain, a range if drawn per episode) and whether its routes are drawn from a
    weighted list of families."""
    kw = eval_env_settings(cfg)[0]
    parts = [f"{kw['drag_law']} law" if "drag_law" in kw else "model law"]
    if "delta_bar" in kw:
        parts.append(f"δ̄ {kw['delta_bar']:g}")
    gain = kw.get("flow_gain", 1.0)
    if isinstance(gain, (list, tuple)):
        parts.append(f"flow x{gain[0]:g}-{gain[1]:g}")
    elif float(gain) != 1.0:
        parts.append(f"flow x{gain:g}")
    if kw.get("families"):
        fams = list(kw["families"])
        parts.append(f"detour {fams.count('detour')} in {len(fams)}")
    return ", ".join(parts)


def curve_groups(runs: Sequence[Path]) -> dict[tuple[tuple[str, ...], str], list]:
    """The runs with an ``evaluations.npz``, grouped by (evaluation routes, training env
    label): ``(run, policy name, label, timesteps, results)`` per run."""
    groups: dict[tuple[tuple[str, ...], str], list] = defaultdict(list)
    for run in runs:
        path = Path(run) / "evaluations.npz"
        if path.is_file():
            d = np.load(path)
            targets, _, name, label, cfg = _run_info(Path(run))
            key = (targets, _env_label(cfg))
            groups[key].append((Path(run), name, label, d["timesteps"], d["results"]))
    return groups


def plot_learning_curves(runs: Sequence[Path], out: Path, rows: Sequence[dict]) -> bool:
    """Mean return (= final score) of each run's EvalCallback against training steps, one
    panel per evaluation set and training env (a stage of a run that changes env gets
    its own), with the baselines on that set as dashed lines: from the evaluated
    ``rows`` for held-out routes, from :func:`eval_set_baselines` for validation routes
    (scored on the panel's first run's env). Labels give each run's sample count and
    wall time."""
    groups = curve_groups(runs)
    if not groups:
        return False
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(groups), figsize=(6 * len(groups), 4), squeeze=False)
    for ax, ((targets, env_label), curves) in zip(axes.flat, groups.items(), strict=True):
        used: set[str] = set()
        for _, name, label, t, r in curves:
            m, s = r.mean(axis=1), r.std(axis=1)
            color = COLORS.get(name)
            if color is None or color in used:  # a second run of one policy: its own colour
                color = next((c for c in EXTRA_COLORS if c not in used), "k")
            used.add(color)
            ax.plot(t, m, marker="o", label=label, color=color)
            ax.fill_between(t, m - s, m + s, alpha=0.2, color=color)
        if VALIDATION in targets:
            base = eval_set_baselines(curves[0][0], cache_dir=out)
            where = f"{len(targets)} validation routes"
        else:
            base = {}
            for p in CURVE_BASELINES:
                v = [r["score"] for r in rows if r["policy"] == p and r["target"] in targets]
                if v:
                    base[p] = float(np.mean(v))
            where = ", ".join(targets) or "?"
        for name, v in base.items():
            ax.axhline(v, ls="--", color=COLORS.get(name, "k"), lw=1, label=f"{name} (same routes)")
        ax.set_xlabel("training steps")
        ax.set_ylabel("eval return = final score Φ")
        ax.set_title(f"EvalCallback on {where}\n(training env: {env_label})", fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "learning_curves.png", dpi=90)
    plt.close(fig)
    return True


# ---- driver -------------------------------------------------------------------------------


def _rrd(results: Sequence[dict[str, Any]], rrd_dir: Path) -> list[Path]:
    from cnt_env import replay

    try:
        replay.import_rerun()
    except ImportError as exc:
        print(f"--rrd skipped: rerun is not installed ({exc}); {replay.INSTALL_HINT}")
        return []
    rrd_dir.mkdir(parents=True, exist_ok=True)
    done, paths = set(), []
    for r in sorted(results, key=lambda r: r["row"]["seed"]):
        key = (r["row"]["policy"], r["row"]["target"])
        if key in done or not r["episode_file"]:
            continue
        done.add(key)
        path = rrd_dir / f"{Path(r['episode_file']).stem}.rrd"  # the episode's name
        replay.record_episode(r["episode_file"], path)
        paths.append(path)
    return paths


def _videos(results: Sequence[dict[str, Any]], video_dir: Path, fmt: str) -> list[Path]:
    """One video (``fmt``: mp4 or gif) per evaluated episode, from its episode file
    (:func:`cnt_env.replay.write_video`); skipped with a message without the video extra."""
    from cnt_env import replay

    video_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for r in results:
        if not r.get("episode_file"):
            continue
        path = video_dir / f"{Path(r['episode_file']).stem}.{fmt}"  # the episode's name
        try:
            replay.write_video(r["episode_file"], path)
        except ImportError as exc:
            print(f"--video skipped: {exc}")
            return paths
        paths.append(path)
    return paths


def evaluate(
    policies: Sequence[str],
    targets: Sequence[str],
    seeds: Sequence[int],
    config: dict[str, Any],
    out: Path,
    models: Path | Sequence[Path] = PRETRAINED,
    runs: Sequence[Path] = (),
    constant_from: Path | None = None,
    jobs: int = 2,
    save_episodes: Path | None = None,
    rrd: Path | None = None,
    reuse: Sequence[Path] = (),
    redo: Sequence[str] = (),
    trust: bool = False,
    video: Path | None = None,
    video_format: str = "mp4",
    custom_routes: Mapping[str, routes.Route] | None = None,
    model_paths: Mapping[str, Path] | None = None,
) -> list[dict[str, Any]]:
    """Run the evaluation and write the tables and plots (module doc). Returns the table.
    ``custom_routes``: routes by name (``--route-file``, corridor task) that ``targets``
    may name besides the held-out ones. ``model_paths``: the model of a policy name that
    is not ``<models>/<name>.zip`` (``cnt-demo``'s short run)."""
    limit_threads()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.time()
    env_kwargs, max_steps = env_settings(config)
    custom = dict(custom_routes or {})
    route_of = None
    if score_mode(env_kwargs) == "corridor":
        route_of = {t: custom[t] if t in custom else routes.held_out(t) for t in targets}
    elif custom:
        raise ValueError("custom routes (--route-file) need the corridor task (score: corridor)")
    t0 = time.perf_counter()
    ctx = mp.get_context("forkserver")
    tmp = None
    if (rrd is not None or video is not None) and save_episodes is None:
        tmp = tempfile.TemporaryDirectory()
        save_episodes = Path(tmp.name)
    # --reuse: each directory read once; the first holding an episode wins. A trained
    # policy's episodes are the same model's only where that run recorded its sha256.
    hashes = {p: model_hashes(p, models, model_paths) for p in policies if p not in BASELINES}
    wanted = {(p, t, int(s)) for p in policies for t in targets for s in seeds}
    old: dict[tuple[str, str, int], dict[str, Any]] = {}
    unverified: set[str] = set()  # reused from a run that recorded no sha256 for it
    for d in reuse:
        theirs = _recorded_hashes(Path(d))
        other = {p for p, h in hashes.items() if p in theirs and h is not None and theirs[p] != h}
        for p in sorted(other):
            print(f"{p}: not reused from {d}, whose {p} was another model")
        loaded = _load_results(Path(d), {w for w in wanted if w[0] not in other}, custom)
        for r in loaded:
            old.setdefault(_episode_key(r["row"]), r)
        for p in sorted({r["row"]["policy"] for r in loaded} & set(hashes) - set(theirs)
                        - set(redo)):  # fmt: skip
            print(f"{p}: {d} records no sha256 of its model (results made before "
                  f"2026-12-07), so its episodes are taken as this model's: pass --redo "
                  f"{p} if it is another")  # fmt: skip
            unverified.add(p)
    reused = {p for p in policies if p not in redo
              and all((p, t, int(s)) in old for t in targets for s in seeds)}  # fmt: skip
    if reused:
        print(f"reusing the episodes of {sorted(reused)} from {list(map(str, reuse))}")
    with ctx.Pool(jobs) as pool:
        specs: dict[str, dict[str, Any]] = {}
        best = None
        if "constant" in policies and "constant" not in reused:
            if constant_from is not None:
                best = json.loads(Path(constant_from).read_text())["best"]
                missing = [t for t in targets if t not in best]
                if missing:
                    raise ValueError(f"{constant_from} has no constant flow for {missing}")
            else:
                best = constant_search(env_kwargs, max_steps, targets, pool, out, route_of)
        t_search = time.perf_counter() - t0
        job_list = []
        for p in policies:
            if p in reused:
                continue
            trained = p not in BASELINES
            members: list[Path] = []
            if trained:
                from policies.sb3 import check_model

                for name in ensemble_members(p):
                    model = model_file(name, models, model_paths)
                    if not model.is_file():
                        raise FileNotFoundError(f"no {name} model at {model} (--models); "
                                                "train one with cnt-train")  # fmt: skip
                    check_model(model, trust=trust)  # refuses before any worker starts
                    members.append(model)
            observed = observation_settings(members) if trained else {}
            if any(env_kwargs.get(k) != v for k, v in observed.items()):
                print(f"{p}: observed as it was trained, {observed}")
            for t in targets:
                spec = {"kind": p}
                if p == "constant":
                    spec.update(vbar=best[t]["vbar"], phi=best[t]["phi"])
                if trained:
                    spec["models"] = [str(m) for m in members]
                    spec["trust"] = bool(trust)
                specs[p] = spec
                for s in seeds:
                    job_list.append({
                        "policy": p, "spec": spec, "target": t, "seed": int(s),
                        "route": custom[t].to_dict() if t in custom else None,
                        "env_kwargs": {**env_kwargs, **observed}, "max_steps": max_steps,
                        "save_dir": str(save_episodes) if save_episodes else None,
                    })  # fmt: skip
        results = _mapped(pool, run_episode, job_list, "episodes")
    results = [r for key, r in old.items() if key[0] in reused] + results
    rows = [r["row"] for r in results]
    _write_csv(out / "episodes.csv", rows)
    _save_results(out, results)
    table = aggregate(rows, policies, targets, seeds)
    _write_csv(out / "results.csv", table)
    overall = {r["policy"]: r for r in table if r["target"] == "ALL"}
    summary = {
        "policies": {
            p: {"score_mean": overall[p]["score_mean"], "score_std": overall[p]["score_std"]}
            for p in policies if p in overall
        },
        "targets": list(targets),
        "seeds": [int(s) for s in seeds],
        "custom_routes": {t: custom[t].to_dict() for t in targets if t in custom},
        # the physics and episode cap the episodes ran on (the surrogate's and the
        # model's results are otherwise alike), and each trained policy's model file
        "env_kwargs": to_jsonable(env_kwargs),
        "max_episode_steps": max_steps,
        "models": {p: (SPLIT if SPLIT in p else "+").join(map(shown_path, spec["models"]))
                   for p, spec in specs.items() if "models" in spec},
        # the model files' sha256 (one per ensemble member), for --reuse to check
        "model_sha256": {p: h for p, h in hashes.items()
                         if h is not None and not (p in reused and p in unverified)},
    }  # fmt: skip
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    (out / "results.md").write_text(markdown_tables(table))
    plot_traces(results, targets, out, route_of)
    if runs:
        plot_learning_curves(runs, out, rows)
    if rrd is not None:
        paths = _rrd(results, Path(rrd))
        if paths:
            print(f"rerun recordings: {len(paths)} in {rrd}")
    if video is not None:
        paths = _videos(results, Path(video), video_format)
        if paths:
            print(f"videos: {len(paths)} in {video}")
    if tmp is not None:
        tmp.cleanup()
    kept = earlier_outputs(out, started)
    if kept:
        print(f"kept in {out} from an earlier evaluation (not written by this one): "
              f"{', '.join(kept)}")  # fmt: skip
    wall = time.perf_counter() - t0
    print(_format_table(table))
    print(f"evaluated {len(job_list)} episodes in {wall:.0f} s (constant search {t_search:.0f} s)")
    return table


#: The files an evaluation writes (module doc); in an ``--out`` used before, those this
#: one did not write stay (a re-run with --reuse keeps learning_curves.png on purpose).
OUTPUT_PATTERNS = ("episodes.*", "results.*", "summary.json", "traces*.png", "traces.npz",
                   "constant_grid.csv", "constant_best.json", "learning_curves.png")  # fmt: skip


def earlier_outputs(out: Path, since: float) -> list[str]:
    """Evaluation outputs in ``out`` last written before ``since`` (a ``time.time()``)."""
    files = {p for pattern in OUTPUT_PATTERNS for p in out.glob(pattern) if p.is_file()}
    return sorted(p.name for p in files if p.stat().st_mtime < since)


def markdown_tables(table: Sequence[dict[str, Any]]) -> str:
    """Two Markdown tables: over all targets (mean ± std over seeds of Φ and its terms,
    normalised score), and Φ per policy and target."""
    overall = [r for r in table if r["target"] == "ALL"]
    cols = ("score", "coverage", "precision", "progress")
    out = ["| policy | score Φ | coverage | precision | progress | normalised |",
           "|---|---|---|---|---|---|"]  # fmt: skip
    for r in overall:
        cells = " | ".join(f"{r[f'{k}_mean']:.3f} ± {r[f'{k}_std']:.3f}" for k in cols)
        out.append(f"| {r['policy']} | {cells} | {_normalised(r)} |")
    if any(math.isnan(r["normalized_score"]) for r in overall):
        out += ["", NO_FLOOR]
    targets = list(dict.fromkeys(r["target"] for r in table if r["target"] != "ALL"))
    policies = [r["policy"] for r in overall]
    cell = {(r["policy"], r["target"]): r for r in table}
    out += ["", "| target | " + " | ".join(policies) + " |",
            "|---|" + "---|" * len(policies)]  # fmt: skip
    for t in targets:
        vals = [cell[(p, t)]["score_mean"] if (p, t) in cell else math.nan for p in policies]
        best = int(np.nanargmax(vals))
        txt = [f"**{v:.3f}**" if i == best else f"{v:.3f}" for i, v in enumerate(vals)]
        out.append(f"| {t} | " + " | ".join(txt) + " |")
    return "\n".join(out) + "\n"


def _format_table(table: Sequence[dict[str, Any]]) -> str:
    lines = [f"{'policy':9s} {'target':17s} {'score':>15s} {'coverage':>15s} "
             f"{'precision':>15s} {'progress':>15s} {'norm':>6s}"]  # fmt: skip
    for r in table:
        cells = " ".join(f"{r[f'{k}_mean']:6.3f} ± {r[f'{k}_std']:5.3f}"
                         for k in ("score", "coverage", "precision", "progress"))  # fmt: skip
        lines.append(f"{r['policy']:9s} {r['target']:17s} {cells} {_normalised(r):>6s}")
    if any(math.isnan(r["normalized_score"]) for r in table):
        lines.append(NO_FLOOR)
    return "\n".join(lines)


#: Why a table has no normalised score.
NO_FLOOR = "n/a: the normalised score needs 'random' among --policies (its floor)"


def _normalised(row: dict[str, Any]) -> str:
    """The row's normalised score to 3 decimals, "n/a" without its floor (random)."""
    x = row["normalized_score"]
    return "n/a" if math.isnan(x) else f"{round(x, 6) + 0.0:.3f}"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cnt-evaluate", description=__doc__.split("\n\n")[0],
                                formatter_class=DefaultsHelp)  # fmt: skip
    p.add_argument("--policies", default=",".join(ALL_POLICIES),
                   help="comma separated: random, constant, scripted, or a model name "
                        "<name> (--models/<name>.zip)")  # fmt: skip
    p.add_argument("--targets", default=None,
                   help="held-out names (routes, or thin targets with score: thin) or "
                        "names of --route-file, comma separated, or all (the held-out set) "
                        "(default: the --route-file's routes if given, else all)")  # fmt: skip
    p.add_argument("--route-file", type=Path, default=None,
                   help="your own routes: a JSON or YAML list of route dicts with a name "
                        "each, or a mapping {name: route dict} (docs/task.md)")  # fmt: skip
    p.add_argument("--seeds", type=seed_list, default="0,1,2",
                   help="comma separated episode seeds")  # fmt: skip
    p.add_argument("--config", type=Path, default=EVAL_CONFIG,
                   help="YAML whose env_kwargs / max_episode_steps set the env")  # fmt: skip
    p.add_argument("--models", type=Path, nargs="+", default=[PRETRAINED],
                   help="directories of the models <policy>.zip, their <policy>_vecnormalize"
                        ".npz + .json and MANIFEST.json; the first holding a name wins "
                        "(--policies a+b: the ensemble of models a and b; 'a|b': a on "
                        "routes without a keep-out, b on routes with one)")  # fmt: skip
    p.add_argument("--trust", action="store_true",
                   help="also load what cannot be loaded without running code from the "
                        "file (a *_vecnormalize.pkl, a zip whose pickled entries cannot be "
                        "rebuilt) and models that fail their MANIFEST.json; only for files "
                        "you trust (docs/security.md)")  # fmt: skip
    p.add_argument("--runs", type=Path, nargs="*", default=[],
                   help="training run directories for the learning curves")  # fmt: skip
    p.add_argument("--constant-from", type=Path, default=None,
                   help="reuse the constant flows of a constant_best.json")  # fmt: skip
    p.add_argument("--out", type=Path, default=None,
                   help="results directory (default: a new runs/evaluate/<task>, never "
                        "the committed training/results unless given)")  # fmt: skip
    p.add_argument("--jobs", type=positive_int, default=2, help="worker processes")
    p.add_argument("--save-episodes", type=Path, default=None,
                   help="save every episode (cnt_env.replay episode npz) here")  # fmt: skip
    p.add_argument("--rrd", type=Path, default=None, help="write rerun recordings here")
    p.add_argument("--video", type=Path, default=None,
                   help="write a video of every evaluated episode here (needs the video "
                        "extra: imageio + imageio-ffmpeg)")  # fmt: skip
    p.add_argument("--video-format", choices=("mp4", "gif"), default="mp4",
                   help="format of the --video files")  # fmt: skip
    p.add_argument("--reuse", type=Path, nargs="*", default=[],
                   help="reuse the episodes of policies fully evaluated in these results "
                        "dirs (episodes.json + traces.npz); run only the others")  # fmt: skip
    p.add_argument("--redo", default="",
                   help="comma separated policies to run again even if --reuse has them "
                        "(e.g. a changed baseline)")  # fmt: skip
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parse_cli(parser, argv)
    try:
        config = load_config(args.config)
        env_kwargs, _ = env_settings(config)
    except ValueError as exc:
        parser.error(f"--config: {exc}")
    custom: dict[str, routes.Route] = {}
    if args.route_file is not None:
        if score_mode(env_kwargs) != "corridor":
            parser.error("--route-file: routes need the corridor task (score: corridor)")
        try:
            custom = routes.load_file(args.route_file)
        except ValueError as exc:
            parser.error(f"--route-file: {exc}")
    held = list(held_out_names(env_kwargs))
    if args.targets is None:
        targets = list(custom) or held
    elif args.targets == "all":  # the held-out set, not the file's routes
        targets = held
    else:
        try:
            targets = held_out_targets(args.targets, [*held, *custom])
        except ValueError as exc:
            parser.error(f"--targets: {exc}")
    for p in csv_list(args.policies):  # before any directory is made
        if p in BASELINES:
            continue
        try:
            members = ensemble_members(p)
        except ValueError as exc:
            parser.error(f"--policies: {exc}")
        for name in members:
            model = model_file(name, args.models)
            if name in BASELINES or not model.is_file():
                parser.error(f"--policies: {name!r} is neither a baseline "
                             f"({', '.join(BASELINES)}) nor a model: there is no {model} "
                             "(--models; a+b: the ensemble of models a and b, a|b: the "
                             "keep-out split)")  # fmt: skip
    for flag in ("out", "save_episodes", "rrd", "video"):
        check_dir_option(parser, flag, getattr(args, flag))
    out = args.out or fresh_dir(Path("runs") / "evaluate" / score_mode(env_kwargs))
    print(f"results -> {out}")
    from policies.sb3 import UntrustedModelError

    try:
        evaluate(csv_list(args.policies), targets, args.seeds, config, out,
                 models=args.models, runs=args.runs, constant_from=args.constant_from,
                 jobs=args.jobs, save_episodes=args.save_episodes, rrd=args.rrd,
                 reuse=args.reuse, redo=csv_list(args.redo),
                 trust=args.trust, video=args.video,
                 video_format=args.video_format, custom_routes=custom)  # fmt: skip
    except (UntrustedModelError, FileNotFoundError) as exc:
        print(f"cnt-evaluate: error: {exc}", file=sys.stderr)
        return 2  # EXIT_USAGE (docs/cli.md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
