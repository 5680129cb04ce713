"""Distil the planning oracle into a residual agent (issue 10): imitation of the rollout
algorithm (``training/oracle.py``) on routes drawn from the training families.

1. **Label.** Oracle episodes on training-family routes (the ``i``-th of ``--families``,
   in turn, at reset seed ``seed0 + i``, each pass over the families at the next of
   the ``--difficulty`` values), each written as ``labels/ep_<i>.npz``: the raw
   observation of every control step, the follower's action, the candidates, their
   rollout scores and the one played. The states are the oracle's own (the first
   iteration of DAgger, Ross et al. 2011). Resumable: a finished episode is not re-run.
   ``--horizon H`` labels with the truncated oracle (``RolloutOracle.horizon``: each
   candidate scored by Φ after H follower steps; linear in the episode's length, so the
   detour family can be labelled too); ``--confirm`` plays a screened departure only
   where its full rollout beats the follower's (``RolloutOracle.confirm``: sparse labels
   that keep the improvement property); one label directory holds one oracle
   (``labels/oracle.json``: its horizon and confirm).
2. **Fit.** A PPO MlpPolicy of the residual config (``configs/ppo_residual.yml``, at
   ``--scale``) regresses its mean action onto the oracle's correction of the follower,
   ``clip((a_oracle - a_follower) / scale, -1, 1)``, where the chosen candidate beats the
   follower's own by more than ``--margin`` (else 0: the follower's action), on
   observations normalised by the labels' statistics. Episodes ``i mod 5 == 4`` are held
   out: the fit keeps the epoch with the lowest error on them.

The model is written as a training run's (``ppo_distil.zip``, its VecNormalize statistics
as ``.npz`` + ``.json``, ``ppo_distil.yml`` with the residual wrapper, ``MANIFEST.json``),
so ``policies.load_policy`` and ``cnt-evaluate --models DIR --policies ppo_distil`` read
it::

    python -m training.distil --out runs/distil --episodes 40 --jobs 2 \
        --max-wall-seconds 3000
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import multiprocessing
import queue
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "training/configs/ppo_residual.yml"
NAME = "ppo_distil"
#: Families labelled by default: all but the detour, whose follower episodes run to the
#: step cap (~90 steps at difficulty 0.2), and an oracle episode costs ~N^2 env steps
#: (~40 CPU-min at ~5 env steps per CPU-s) against ~2-6 min for the others.
LABEL_FAMILIES = ("straight", "l_route", "u_route", "staircase", "arc", "pads", "band")


def _env_kwargs(difficulty: float) -> tuple[dict[str, Any], int]:
    from .common import env_settings, load_config

    env_kwargs, max_steps = env_settings(load_config(CONFIG))
    return {**env_kwargs, "difficulty": float(difficulty)}, max_steps


def label_episode(job: dict[str, Any]) -> dict[str, Any]:
    """One oracle episode; writes ``job["path"]`` and returns its summary."""
    from policies import RouteFollower

    from .common import limit_threads, make_env
    from .oracle import RolloutOracle

    limit_threads()
    env_kwargs, max_steps = _env_kwargs(job["difficulty"])
    env = make_env(env_kwargs, max_steps)
    follower = RouteFollower.from_env(env)
    families = job["families"]
    family = families[job["index"] % len(families)]
    obs, info = env.reset(seed=job["seed"], options={"target": family})
    follower.reset(job["seed"])
    oracle = RolloutOracle(env, follower, horizon=job.get("horizon"),
                           confirm=bool(job.get("confirm", False)))  # fmt: skip
    t0 = time.perf_counter()
    rows: dict[str, list] = {"obs": [], "follower": [], "candidates": [], "scores": [],
                             "chosen": []}  # fmt: skip
    while True:
        cands, scores, k = oracle.choose(obs, info)
        for key, v in zip(rows, (obs, cands[0], cands, scores, k), strict=True):
            rows[key].append(np.asarray(v))
        obs, _, term, trunc, info = env.step(cands[k])
        if term or trunc:
            break
    env.close()
    summary = {"index": job["index"], "seed": job["seed"], "family": family,
               "difficulty": job["difficulty"], "steps": len(rows["chosen"]),
               "deviations": int(sum(int(c) > 0 for c in rows["chosen"])),
               "horizon": oracle.horizon, "confirm": oracle.confirm,
               # the first base rollout: the follower's final score, unless truncated
               "follower_score": (float(rows["scores"][0][0])
                                  if oracle.horizon is None or oracle.confirm else None),
               "oracle_score": float(info["score"]),
               "rollouts": oracle.rollouts,
               "wall_s": round(time.perf_counter() - t0, 1)}  # fmt: skip
    path = Path(job["path"])
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **{k: np.stack(v) for k, v in rows.items()},
             summary=np.array(json.dumps(summary)))  # fmt: skip
    tmp.replace(path)
    return summary


def label(out: Path, episodes: int, seed0: int, difficulty: list[float], families: list[str],
          jobs: int, deadline: float,
          horizon: int | None = None, confirm: bool = False) -> list[dict[str, Any]]:  # fmt: skip
    """Run the missing episodes of ``out/labels`` until ``deadline`` (perf_counter);
    episodes still running at the deadline are abandoned (not written). Refuses a
    directory labelled with another oracle (``horizon``, ``confirm``)."""
    labels = out / "labels"
    labels.mkdir(parents=True, exist_ok=True)
    meta = labels / "oracle.json"
    want = {"horizon": horizon, "confirm": bool(confirm)}
    had: dict[str, Any] = {"horizon": None, "confirm": False}  # labelled before the options
    if meta.is_file():
        try:
            stored = json.loads(meta.read_text())
            had = {"horizon": stored["horizon"], "confirm": bool(stored.get("confirm", False))}
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise SystemExit(f"{meta} is unreadable ({exc}); delete it only if every "
                             f"label in {labels} has {want}") from exc  # fmt: skip
    elif not any(labels.glob("ep_*.npz")):
        had = want
    if had != want:
        raise SystemExit(f"{labels} was labelled with horizon {had['horizon']} and confirm "
                         f"{had['confirm']}, not horizon {horizon} and confirm {confirm}: "
                         "resume with those options or use another --out")  # fmt: skip
    meta.write_text(json.dumps(want))
    todo = [{"index": i, "seed": seed0 + i, "families": families, "horizon": horizon,
             "confirm": bool(confirm),
             "difficulty": difficulty[(i // len(families)) % len(difficulty)],
             "path": str(labels / f"ep_{i}.npz")}
            for i in range(episodes) if not (labels / f"ep_{i}.npz").is_file()]  # fmt: skip
    done = []
    for s in run_until(label_episode, todo, jobs, deadline):
        done.append(s)
        print(json.dumps(s), flush=True)
    return done


def run_until(fn: Callable[[Any], Any], items: list[Any], jobs: int,
              deadline: float) -> Iterator[Any]:  # fmt: skip
    """``fn(item)`` for each of ``items`` on ``jobs`` worker processes, in submission
    order, yielding the results as they finish until ``deadline`` (perf_counter). Then
    the pool is terminated: a task still running is abandoned and must not hold a core
    past the budget. An exception in a task is raised here."""
    results: queue.SimpleQueue = queue.SimpleQueue()
    with multiprocessing.Pool(jobs) as pool:  # leaving the block terminates the workers
        for item in items:
            pool.apply_async(fn, (item,), callback=results.put, error_callback=results.put)
        for _ in items:
            left = deadline - time.perf_counter()
            if left <= 0:
                return
            try:
                res = results.get(timeout=left)
            except queue.Empty:
                return
            if isinstance(res, BaseException):
                raise res
            yield res


def load_labels(out: Path) -> list[dict[str, np.ndarray]]:
    """The finished label episodes of ``out/labels`` in index order (a ``.tmp.npz`` left
    by an abandoned episode is not one)."""
    paths = [p for p in (out / "labels").glob("ep_*.npz") if not p.name.endswith(".tmp.npz")]
    eps = []
    for path in sorted(paths, key=lambda p: int(p.stem[3:])):
        with np.load(path, allow_pickle=False) as d:
            ep = {k: d[k] for k in d.files}
        ep["summary"] = json.loads(str(ep["summary"]))
        eps.append(ep)
    return eps


def held_out(ep: dict[str, Any]) -> bool:
    """Whether label episode ``ep`` is one the fit holds out (index mod 5 == 4)."""
    return ep["summary"]["index"] % 5 == 4


def targets(ep: dict[str, np.ndarray], scale: float, margin: float) -> np.ndarray:
    """The residual the agent should output at each step of ``ep`` (module doc)."""
    k = ep["chosen"].astype(int)
    n = np.arange(len(k))
    gain = ep["scores"][n, k] - ep["scores"][:, 0]
    r = (ep["candidates"][n, k] - ep["follower"]) / scale
    r[gain <= margin] = 0.0
    return np.clip(r, -1.0, 1.0).astype(np.float32)


def fit(out: Path, scale: float, margin: float, epochs: int, seed: int, models: Path,
        limit: int | None = None) -> dict[str, Any]:  # fmt: skip
    """Fit the distilled residual agent on the labels of ``out`` (module doc) and save it
    in ``models`` as ``ppo_distil.zip`` and the files beside it, from the label episodes
    of index < ``limit`` if given (a learning curve in the number of labels); returns the
    fit report."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from policies.residual import WRAPPER, pin_base
    from policies.sb3 import save_vecnormalize, vecnormalize_path, write_manifest

    from .common import ENV_ID, ResidualAction, algo_kwargs, limit_threads, load_config, make_env

    limit_threads()
    eps = [e for e in load_labels(out) if limit is None or e["summary"]["index"] < limit]
    if not eps:
        raise SystemExit(f"no labels in {out / 'labels'}: run the label phase first")
    config = load_config(CONFIG)
    difficulty = max(e["summary"]["difficulty"] for e in eps)
    env_kwargs, max_steps = _env_kwargs(difficulty)
    train = [e for e in eps if not held_out(e)] or eps
    valid = [e for e in eps if held_out(e)]
    x = np.concatenate([e["obs"] for e in train]).astype(np.float64)
    y = np.concatenate([targets(e, scale, margin) for e in train])

    venv = DummyVecEnv([lambda: ResidualAction(make_env(env_kwargs, max_steps), "scripted",
                                               scale)])  # fmt: skip
    venv = VecNormalize(venv, gamma=float(config.get("gamma", 0.99)), norm_reward=True)
    # observation statistics of the labels; a feature constant in the labels (the
    # keep-out features, when no detour is labelled) is normalised to ~0 wherever it is
    # not, so the agent ignores what it never saw instead of reading +-clip_obs
    var = x.var(axis=0)
    venv.obs_rms.mean = x.mean(axis=0)
    venv.obs_rms.var = np.where(var < 1e-8, 1e12, var)
    venv.obs_rms.count = float(len(x))
    torch.manual_seed(seed)
    model = PPO(config.get("policy", "MlpPolicy"), venv, seed=seed, device="cpu",
                **algo_kwargs(config))  # fmt: skip
    policy = model.policy

    def normalised(obs: np.ndarray) -> torch.Tensor:
        return torch.as_tensor(venv.normalize_obs(obs.astype(np.float32)), dtype=torch.float32)

    def mean_action(obs: torch.Tensor) -> torch.Tensor:
        return policy.get_distribution(obs).distribution.mean

    def mse(obs: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return torch.mean((mean_action(obs) - target) ** 2)

    xt, yt = normalised(x), torch.as_tensor(y)
    xv = normalised(np.concatenate([e["obs"] for e in valid])) if valid else None
    yv = (
        torch.as_tensor(np.concatenate([targets(e, scale, margin) for e in valid]))
        if valid
        else None
    )
    opt = torch.optim.Adam(policy.parameters(), lr=1e-3)
    gen = torch.Generator().manual_seed(seed)
    best = (math.inf, 0, copy.deepcopy(policy.state_dict()))
    for epoch in range(1, epochs + 1):
        for idx in torch.randperm(len(xt), generator=gen).split(64):
            loss = mse(xt[idx], yt[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
        if xv is not None:
            with torch.no_grad():  # early stopping on the held-out episodes
                v = float(mse(xv, yv))
            if v < best[0]:
                best = (v, epoch, copy.deepcopy(policy.state_dict()))
    if xv is not None:
        policy.load_state_dict(best[2])
    with torch.no_grad():
        report = {
            "episodes": len(eps), "train_states": len(xt),
            "epoch": best[1] if xv is not None else epochs,
            "train_mse": float(mse(xt, yt)),
            "train_zero_mse": float(torch.mean(yt**2)),
            "valid_states": 0 if xv is None else len(xv),
            "valid_mse": None if xv is None else float(mse(xv, yv)),
            "valid_zero_mse": None if yv is None else float(torch.mean(yv**2)),
        }  # fmt: skip

    models = Path(models)
    models.mkdir(parents=True, exist_ok=True)
    path = models / f"{NAME}.zip"
    model.save(str(path))
    save_vecnormalize(venv, vecnormalize_path(path))
    entry = dict(config)
    entry["env_kwargs"] = {**entry.get("env_kwargs", {}), "difficulty": difficulty}
    entry["env_wrapper"] = [{WRAPPER: {"base": "scripted", "scale": scale}}]
    entry = pin_base(entry, venv.get_attr("score_mode", [0])[0])
    summaries = [e["summary"] for e in eps]
    entry["distil"] = {"scale": scale, "margin": margin, "epochs": epochs, "seed": seed,
                       "fit": report, "label_wall_s": sum(s["wall_s"] for s in summaries),
                       "episodes": summaries}  # fmt: skip
    path.with_suffix(".yml").write_text(yaml.safe_dump({ENV_ID: entry}, sort_keys=False))
    write_manifest(models)
    venv.close()
    return report


def validate(model_path: Path, n_routes: int = 4) -> dict[str, Any]:
    """Scores of the agent at ``model_path`` and of the follower on the training config's
    validation routes (``training.common.HeldOutCycle``'s: reset seeds 50 000 + i, never
    a held-out test route): what a variant of the fit is chosen on."""
    from policies import RouteFollower, load_policy

    from .common import VALIDATION_SEED0, env_settings, load_config, make_env
    from .oracle import finish

    env_kwargs, max_steps = env_settings(load_config(CONFIG))
    env = make_env(env_kwargs, max_steps)
    scores: dict[str, list[float]] = {"agent": [], "follower": []}
    for name, pol in (("agent", load_policy(model_path, env=env)),
                      ("follower", RouteFollower.from_env(env))):  # fmt: skip
        for i in range(n_routes):
            obs, info = env.reset(seed=VALIDATION_SEED0 + i)
            pol.reset(VALIDATION_SEED0 + i)
            scores[name].append(finish(env, pol, obs, False, False, info))
    env.close()
    return {k: {"mean": float(np.mean(v)), "routes": v} for k, v in scores.items()}


def main(argv: list[str] | None = None) -> int:
    from cnt_env.cli.common import nonnegative_int

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("runs/distil"))
    ap.add_argument("--episodes", type=int, default=40)
    ap.add_argument("--seed0", type=int, default=20_000, help="reset seed of episode 0")
    ap.add_argument(
        "--difficulty", default="0.2,0.5", help="route difficulties, one per pass over the families"
    )
    ap.add_argument(
        "--families",
        default=",".join(LABEL_FAMILIES),
        help="route families labelled in turn (default: all but detour)",
    )
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument(
        "--max-wall-seconds",
        type=float,
        default=3000.0,
        help="stop labelling then (the fit takes about a minute more)",
    )
    ap.add_argument(
        "--scale",
        type=float,
        default=0.6,
        help="residual scale: 0.6 lets it add the oracle's 0.4 rad turns",
    )
    ap.add_argument(
        "--margin",
        type=float,
        default=0.0,
        help="a candidate must beat the follower's score by more to count",
    )
    ap.add_argument(
        "--horizon",
        type=nonnegative_int,
        default=None,
        metavar="H",
        help="truncated oracle: score candidates H follower steps on (default: to the end)",
    )
    ap.add_argument(
        "--confirm",
        action="store_true",
        help="with --horizon: play a screened departure only if its full rollout wins",
    )
    ap.add_argument("--epochs", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--fit-only", action="store_true")
    ap.add_argument("--model-dir", type=Path, default=None, help="default: OUT/model")
    ap.add_argument(
        "--fit-episodes",
        type=int,
        default=None,
        metavar="N",
        help="fit on the label episodes of index < N only",
    )
    ap.add_argument(
        "--validate",
        type=int,
        default=4,
        metavar="N",
        help="score the fitted agent and the follower on N validation routes",
    )
    from .common import parse_cli

    args = parse_cli(ap, argv)
    if args.confirm and args.horizon is None:
        ap.error("--confirm needs --horizon (without one every rollout is full)")
    t0 = time.perf_counter()
    if not args.fit_only:
        families = [f for f in args.families.split(",") if f]
        difficulty = [float(d) for d in args.difficulty.split(",") if d]
        label(args.out, args.episodes, args.seed0, difficulty, families, args.jobs,
              t0 + args.max_wall_seconds, args.horizon, args.confirm)  # fmt: skip
    models = args.model_dir or args.out / "model"
    report = fit(
        args.out, args.scale, args.margin, args.epochs, args.seed, models, args.fit_episodes
    )
    report["wall_s"] = round(time.perf_counter() - t0, 1)
    print(json.dumps(report), flush=True)
    if args.validate:
        print(json.dumps(validate(models / f"{NAME}.zip", args.validate)))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())
