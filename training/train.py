"""Train PPO, SAC or a recurrent PPO on CNTDeposit-v0 (``cnt-train``).

    cnt-train --algo ppo|sac|ppo_lstm [--config training/configs/ppo.yml] [--seed 0]
              [--n-timesteps N] [--max-wall-seconds S] [--out runs/] [--n-envs 2]
              [--trained-agent runs/ppo_s0/ppo.zip [--new-base-options]]

One run directory ``<out>/<algo>_s<seed>/`` (``_2``, ``_3``, ... when it exists: a run
never overwrites an earlier one) holds:

* ``<algo>.zip``; the VecNormalize statistics beside it as
  ``<algo>_vecnormalize.npz`` + ``.json`` (data, no pickle: :func:`policies.load_policy`
  reads them; docs/security.md) and VecNormalize's own ``<algo>_vecnormalize.pkl``
  (``VecNormalize.load``, for SB3 / rl-zoo tools; a pickle: load only your own);
* ``MANIFEST.json``: the sha256 of the model files (zip, statistics, ``<algo>.yml``),
  checked by :func:`policies.load_policy`;
* ``best_model.zip`` (EvalCallback: the best mean return on its evaluation routes) with
  the VecNormalize statistics of that moment (``best_model_vecnormalize.npz`` + ``.json``)
  and ``best_model.yml``, so it loads like the final model;
* ``config.yml`` and ``<algo>.yml``: the resolved config (hyperparameters, env kwargs,
  seed, budget, versions, wall time);
* ``evaluations.npz`` (EvalCallback on held-out targets) and ``learning_curve.csv``;
* ``checkpoints/`` (CheckpointCallback, with the VecNormalize pickle and npz + JSON), ``monitor/``
  (Monitor CSVs), ``tb/`` (tensorboard: SB3's scalars and the task metrics under ``task/``: score,
  coverage, progress, inside, shorts, completion of every finished episode).

Configs are rl-zoo style (one YAML file per algorithm, an entry ``CNTDeposit-v0``):
the algorithm's keyword arguments (``lin_<v>`` schedules, ``policy_kwargs`` as a string
``"dict(net_arch=[64, 64])"``), ``n_timesteps``, ``policy``, ``n_envs``,
``normalize: true``, ``env_kwargs`` (the env's keywords and ``max_episode_steps``, the
TimeLimit), ``env_wrapper`` (``training.common.ResidualAction`` for a residual agent)
and ``callback`` (``training.callbacks.HeldOutEval: {eval_targets, eval_freq,
n_eval_episodes}``, ``training.callbacks.Checkpoint: {save_freq}``,
``training.callbacks.Curriculum: {stages: [{at, families, difficulty}, ...]}``). The older
top-level keys (``max_episode_steps``, ``eval_*``, ``save_freq``, ``residual``) still
work.
"""

from __future__ import annotations

import argparse
import csv
import platform
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from cnt_env.io import to_jsonable
from policies.mkl import check as check_mkl
from policies.residual import pin_base, residual_settings
from policies.sb3 import (
    ALGOS,
    algo_class,
    check_model,
    file_sha256,
    frame_stack,
    model_config,
    model_files,
    restore_vecnormalize,
    safe_custom_objects,
    save_vecnormalize,
    vecnormalize_path,
    write_manifest,
)

from .callbacks import make_curriculum, make_task_metrics
from .common import (
    CONFIG_DIR,
    DEFAULT_N_ENVS,
    ENV_ID,
    DefaultsHelp,
    HeldOutCycle,
    ResidualAction,
    algo_kwargs,
    check_callbacks,
    check_dir_option,
    check_run_config,
    curriculum_settings,
    env_settings,
    eval_env_settings,
    eval_settings,
    fresh_dir,
    limit_threads,
    load_config,
    make_env,
    normalize_settings,
    observation_mode,
    parse_cli,
    positive_float,
    positive_int,
    score_mode,
    seed_int,
)

__all__ = ["main", "train"]


def _callbacks_module():
    from stable_baselines3.common.callbacks import BaseCallback

    class ProgressBar(BaseCallback):
        """tqdm progress bar (SB3's own needs ``rich`` as well)."""

        def __init__(self, total: int) -> None:
            super().__init__()
            self.total = total
            self.bar = None

        def _on_training_start(self) -> None:
            from tqdm.auto import tqdm

            self.bar = tqdm(
                total=self.total, unit="step", dynamic_ncols=True, file=sys.stderr, mininterval=2.0
            )

        def _on_step(self) -> bool:
            self.bar.update(self.training_env.num_envs)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    class WallClockLimit(BaseCallback):
        """Stop training after ``seconds`` of wall time (the demo's budget)."""

        def __init__(self, seconds: float) -> None:
            super().__init__()
            self.seconds = seconds
            self.t0 = 0.0

        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()

        def _on_step(self) -> bool:
            return time.perf_counter() - self.t0 < self.seconds

    return ProgressBar, WallClockLimit


def _has_tensorboard() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


def train(
    algo: str,
    config: dict[str, Any],
    out: Path,
    seed: int = 0,
    vec_env: str | None = None,
    max_wall_seconds: float | None = None,
    progress_bar: bool = True,
    verbose: int = 0,
    trained_agent: Path | None = None,
    new_base_options: bool = False,
) -> Path:
    """Train ``algo`` with ``config`` (an rl-zoo entry); returns the model path.

    ``trained_agent``: a model saved by cnt-train (``.zip`` with its ``.yml`` and
    VecNormalize statistics) to go on training instead of a new one (rl-zoo's
    ``--trained-agent``), e.g. on other physics (:func:`check_trained_agent`). The
    config's hyperparameters replace the saved ones, its schedules start again, and the
    step count starts at 0; the run's ``config.yml`` records the agent's earlier run.
    ``new_base_options``: the agent goes on over the config's options of its base follower
    even where they differ from those it was trained over (recorded as ``base_kwargs_was``)."""
    limit_threads()
    mkl_branch = check_mkl()  # the torch products' code path (policies/mkl.py)
    import stable_baselines3
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, EvalCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.monitor import Monitor
    from stable_baselines3.common.vec_env import (
        DummyVecEnv,
        SubprocVecEnv,
        VecFrameStack,
        VecNormalize,
        VecTransposeImage,
    )

    algo = algo.lower()
    cls = algo_class(algo)
    env_kwargs, max_steps = env_settings(config)
    check_run_config(config)
    check_callbacks(config)  # the callbacks, checked before any env is built
    stages = curriculum_settings(config)
    earlier = (None if trained_agent is None
               else check_trained_agent(trained_agent, algo, config, new_base_options))  # fmt: skip
    n_envs = int(config.get("n_envs", DEFAULT_N_ENVS))
    vec_env = vec_env or config.get("vec_env", "subproc")
    run = Path(out)
    run.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()

    residual = residual_settings(config)
    wrapper = ResidualAction if residual is not None else None
    venv = make_vec_env(
        ENV_ID,
        n_envs=n_envs,
        seed=seed,
        monitor_dir=str(run / "monitor"),
        env_kwargs={**env_kwargs, "max_episode_steps": max_steps},
        vec_env_cls=SubprocVecEnv if vec_env == "subproc" and n_envs > 1 else DummyVecEnv,
        wrapper_class=wrapper,
        wrapper_kwargs=residual or None,
    )
    score_mode = venv.get_attr("score_mode", [0])[0]
    obs_mode = observation_mode(config)
    norm = normalize_settings(config, obs_mode=obs_mode)
    if norm:
        venv = VecNormalize(venv, gamma=float(config.get("gamma", 0.99)), **norm)
    normalizer = venv  # what is saved as the VecNormalize statistics
    n_stack = frame_stack(config)
    if n_stack > 1:  # rl-zoo's order: the stack of normalised observations
        venv = VecFrameStack(venv, n_stack)

    tb = str(run / "tb") if _has_tensorboard() else None
    if tb is None:
        print("tensorboard is not installed: no tensorboard logs (pip install tensorboard)")
    kwargs = dict(seed=seed, tensorboard_log=tb, verbose=verbose, device="cpu")
    if trained_agent is None:
        model = cls(config.get("policy", "MlpPolicy"), venv, **kwargs, **algo_kwargs(config))
    else:  # the saved weights; the config's hyperparameters (SB3 checks policy_kwargs)
        custom = safe_custom_objects(trained_agent, algo)
        model = cls.load(str(trained_agent), env=venv, custom_objects=custom, **kwargs,
                         **algo_kwargs(config))  # fmt: skip
        if norm:
            restore_vecnormalize(normalizer, vecnormalize_path(trained_agent))

    callbacks = [make_task_metrics()]
    total = int(config["n_timesteps"])
    if stages:
        callbacks.append(make_curriculum([(int(at * total), d) for at, d in stages]))
    # validation routes: drawn as the end of the curriculum draws them (the one aimed at)
    eval_kwargs = eval_env_settings(config)[0]
    for _, draw in stages:
        eval_kwargs.update(draw)
    ev = eval_settings(config)
    if ev["eval_targets"] and ev["eval_freq"] > 0:

        def eval_env_fn():
            env = HeldOutCycle(make_env(eval_kwargs, max_steps), ev["eval_targets"])
            return Monitor(ResidualAction(env, **residual) if wrapper else env)

        class SaveBestStats(BaseCallback):
            """On a new best: the VecNormalize statistics of that moment beside
            best_model.zip, so the best model loads with its own normalisation."""

            def _on_step(self) -> bool:
                venv = self.model.get_vec_normalize_env()
                if venv is not None:
                    save_vecnormalize(venv, vecnormalize_path(run / "best_model.zip"))
                return True

        eval_env = DummyVecEnv([eval_env_fn])
        if norm:
            eval_env = VecNormalize(eval_env, training=False, norm_reward=False,
                                    norm_obs=bool(norm["norm_obs"]),
                                    norm_obs_keys=norm.get("norm_obs_keys"))  # fmt: skip
        if n_stack > 1:
            eval_env = VecFrameStack(eval_env, n_stack)
        if obs_mode != "vector":  # as SB3 wraps the training env for its CNN: the
            eval_env = VecTransposeImage(eval_env)  # chains must match to sync statistics
        callbacks.append(
            EvalCallback(
                eval_env,
                n_eval_episodes=ev["n_eval_episodes"],
                eval_freq=max(1, ev["eval_freq"] // n_envs),
                log_path=str(run),
                best_model_save_path=str(run),  # best_model.zip
                callback_on_new_best=SaveBestStats() if norm else None,
                deterministic=True,
                verbose=verbose,
            )
        )
    if ev["save_freq"] > 0:
        ckpt = _checkpoint_callback(CheckpointCallback)(
            max(1, ev["save_freq"] // n_envs),
            str(run / "checkpoints"),
            name_prefix=algo,
            save_vecnormalize=bool(norm),
        )
        callbacks.append(ckpt)
    ProgressBar, WallClockLimit = _callbacks_module()
    if progress_bar:
        callbacks.append(ProgressBar(total))
    if max_wall_seconds:
        callbacks.append(WallClockLimit(float(max_wall_seconds)))

    model.learn(total_timesteps=total, callback=callbacks, tb_log_name=algo)
    model_path = run / f"{algo}.zip"
    model.save(str(model_path))
    if norm:
        stem = vecnormalize_path(model_path)
        normalizer.save(str(stem))  # VecNormalize's own format (pickle), VecNormalize.load
        save_vecnormalize(normalizer, stem)  # npz + JSON, what policies.load_policy reads
    physics = {  # the drag law and mesh the envs resolved (pin_physics)
        "drag_law": str(venv.get_attr("config", [0])[0].drag_law),
        "delta_bar": float(venv.get_attr("params", [0])[0].delta_bar),
    }
    venv.close()
    wall = time.perf_counter() - t_start

    _write_learning_curve(run)
    resolved = {
        # a residual agent's config pins its base's options (policies/residual.py)
        ENV_ID: to_jsonable(pin_physics(pin_base(config, score_mode), physics)),
        "run": {
            "algo": algo,
            "seed": seed,
            "vec_env": vec_env,
            "n_envs": n_envs,
            "timesteps_done": int(model.num_timesteps),
            "max_wall_seconds": max_wall_seconds,
            "wall_time_s": round(wall, 1),
            "steps_per_s": round(model.num_timesteps / wall, 2),
            "argv": sys.argv,
            "trained_agent": earlier,
            "mkl_branch": mkl_branch,
            "versions": {
                "python": platform.python_version(),
                "stable_baselines3": stable_baselines3.__version__,
                "numpy": np.__version__,
            },
        },
    }
    models = [model_path, run / "best_model.zip"]
    # config.yml, and beside each model for policies.load_policy (the residual base, the
    # env settings)
    text = yaml.safe_dump(resolved, sort_keys=False)
    for path in [run / "config.yml", *(m.with_suffix(".yml") for m in models if m.is_file())]:
        path.write_text(text)
    write_manifest(run, [f.name for m in models for f in model_files(m) if f.is_file()])
    print(f"{algo}: {model.num_timesteps} steps in {wall:.0f} s -> {model_path}")
    return model_path


def _but_options(residual: dict) -> dict:
    """Residual settings without the base's options (``base_kwargs``)."""
    return {k: v for k, v in residual.items() if k != "base_kwargs"}


def check_trained_agent(
    path: Path, algo: str, config: dict[str, Any], new_base_options: bool = False
) -> dict[str, Any]:
    """Refuse to go on training the model at ``path`` with ``config`` unless the agent it
    makes acts on the same thing: the same algorithm, a residual agent's same base with the
    same pinned options (``new_base_options``: other options of the same base are allowed,
    and recorded as ``base_kwargs_was``), the same frame stack, and VecNormalize statistics
    if (and only if) the config normalises. The spaces and ``policy_kwargs`` are checked by
    SB3 when it loads. Returns the record of the agent's earlier run (path, sha256, its
    ``run``)."""
    path = Path(path)
    try:
        resolved = model_config(path)  # yaml.safe_load
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path.with_suffix('.yml')}, the resolved config beside the "
                         "model, is not valid YAML: restore it from the run directory "
                         "the model came from") from exc  # fmt: skip
    if not isinstance(resolved, dict):
        raise ValueError(f"{path.with_suffix('.yml')} is not a resolved config (a mapping)")
    run = resolved.get("run")
    trained_algo = run.get("algo") if isinstance(run, dict) else None
    if trained_algo not in (None, algo):
        raise ValueError(f"{path.name} is a {trained_algo} agent; pass --algo {trained_algo}")
    check_model(path, algo)  # the manifest; nothing is unpickled
    saved = resolved.get(ENV_ID)
    if not isinstance(saved, dict):
        raise ValueError(f"{path.with_suffix('.yml')}, the resolved config cnt-train "
                         "writes beside a model, is missing: cannot tell what the agent "
                         "acts on")  # fmt: skip
    has_stats = vecnormalize_path(path).with_suffix(".npz").is_file()
    record = check_acts_alike(saved, config, new_base_options, has_stats, path.name)
    return {"path": str(path), "sha256": file_sha256(path), "run": run, **record}


def check_acts_alike(saved: dict[str, Any], config: dict[str, Any], new_base_options: bool,
                     normalised: bool, name: str) -> dict[str, Any]:  # fmt: skip
    """Refuse ``config`` to go on training an agent trained with the config entry ``saved``
    (``normalised``: with VecNormalize statistics) unless the agent acts on the same thing
    (:func:`check_trained_agent`; ``name`` names the agent in the errors). Returns
    ``{"base_kwargs_was": ...}`` when only the base's options differ and
    ``new_base_options`` allows it, else ``{}``."""
    env_kwargs, _ = env_settings(config)
    mode = score_mode(env_kwargs)
    was = to_jsonable(residual_settings(pin_base(saved, mode)))
    now = to_jsonable(residual_settings(pin_base(config, mode)))
    for settings in (was, now):  # which routes go to the follower: not what the network acts on
        if settings is not None:
            settings.pop("keepout_headings", None)
    record: dict[str, Any] = {}
    if was != now:
        same_base = None not in (was, now) and _but_options(was) == _but_options(now)
        if not (new_base_options and same_base):
            raise ValueError(f"{name} was trained with the residual settings {was}; "
                             f"this config gives {now}: set the config's ResidualAction to "
                             "the agent's (or pass --new-base-options if only the base's "
                             "options differ)")  # fmt: skip
        record["base_kwargs_was"] = was["base_kwargs"]
    if frame_stack(saved) != frame_stack(config):
        raise ValueError(f"{name} was trained on a frame stack of {frame_stack(saved)}, "
                         f"the config asks for {frame_stack(config)}")  # fmt: skip
    if normalised != bool(normalize_settings(config, obs_mode=observation_mode(config))):
        raise ValueError(f"{name} was trained {'with' if normalised else 'without'} "
                         "VecNormalize statistics (normalize: true) and the config "
                         f"{'does not normalise' if normalised else 'normalises'}")  # fmt: skip
    return record


def _checkpoint_callback(base):
    """SB3's CheckpointCallback (``base``) that also saves the VecNormalize statistics of
    each checkpoint as npz + JSON beside it (``<algo>_<n>_steps_vecnormalize``)."""

    class Checkpoint(base):
        def _on_step(self) -> bool:
            ok = super()._on_step()
            venv = self.model.get_vec_normalize_env()
            if self.n_calls % self.save_freq == 0 and venv is not None:
                save_vecnormalize(venv, vecnormalize_path(self._checkpoint_path(extension="zip")))
            return ok

    return Checkpoint


def pin_physics(entry: dict[str, Any], physics: dict[str, Any]) -> dict[str, Any]:
    """A copy of the config entry ``entry`` whose ``env_kwargs`` hold the drag law and
    ``delta_bar`` the training envs ran (``physics``) where it left them to the env's
    defaults: written beside a trained model (and in the run's ``config.yml``), so that
    a later change of the env's default physics changes neither the env the model loads
    with nor what the run's record says it trained on (the runs of 2026-11-25/26 predate
    the pin, and their configs read as the model law, which they were not)."""
    kwargs = dict(entry.get("env_kwargs") or {})
    for key, value in physics.items():
        kwargs.setdefault(key, value)
    return {**entry, "env_kwargs": kwargs}


def _write_learning_curve(run: Path) -> None:
    """``evaluations.npz`` (EvalCallback) as a CSV: timesteps, mean/std of the return
    (= the final agreement score, rewards being potential differences) over episodes."""
    path = run / "evaluations.npz"
    if not path.is_file():
        return
    data = np.load(path)
    with (run / "learning_curve.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["timesteps", "return_mean", "return_std", "ep_length_mean"])
        for t, r, n in zip(data["timesteps"], data["results"], data["ep_lengths"], strict=True):
            w.writerow([int(t), float(np.mean(r)), float(np.std(r)), float(np.mean(n))])


#: the config of ``--algo`` without ``--config`` where it is not ``<algo>.yml``: the
#: recurrent policy's only measured config (training/results/route_runs/lstm_two40_s1/)
DEFAULT_CONFIG = {"ppo_lstm": "ppo_lstm_residual_recipe.yml"}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="cnt-train", description=__doc__.split("\n\n")[0],
                                formatter_class=DefaultsHelp)  # fmt: skip
    p.add_argument("--algo", choices=ALGOS, required=True,
                   help="algorithm (ppo_lstm: sb3-contrib's RecurrentPPO)")  # fmt: skip
    p.add_argument("--config", type=Path, default=None,
                   help="rl-zoo style YAML (default: training/configs/<algo>.yml; for "
                        "ppo_lstm ppo_lstm_residual_recipe.yml)")  # fmt: skip
    p.add_argument("--seed", type=seed_int, default=0, help="seed of the model and the envs")
    p.add_argument("--n-timesteps", type=positive_int, default=None,
                   help="override n_timesteps")  # fmt: skip
    p.add_argument("--n-envs", type=positive_int, default=None, help="override n_envs")
    p.add_argument("--max-episode-steps", type=positive_int, default=None,
                   help="override the config's TimeLimit cap")  # fmt: skip
    p.add_argument("--max-wall-seconds", type=positive_float, default=None,
                   help="stop training after this wall time")  # fmt: skip
    p.add_argument("--vec-env", choices=("subproc", "dummy"), default=None,
                   help="vector env (None: the config's, else subproc)")  # fmt: skip
    p.add_argument("--trained-agent", type=Path, default=None,
                   help="a model saved by cnt-train (.zip) to go on training (rl-zoo's "
                        "--trained-agent; same base, spaces and policy_kwargs)")  # fmt: skip
    p.add_argument("--new-base-options", action="store_true",
                   help="with --trained-agent: go on over the config's options of the "
                        "agent's base follower where they differ from its own")  # fmt: skip
    p.add_argument("--out", type=Path, default=Path("runs"), help="parent of the run directory")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("-v", "--verbose", type=int, default=0, help="SB3 verbosity")
    return p


def check_config(config: dict[str, Any]) -> None:
    """Every check of a config that needs no env (ValueError saying what is wrong): the
    run's numbers, the callbacks and the curriculum."""
    check_run_config(config)
    check_callbacks(config)
    curriculum_settings(config)


def _resolved_config(args: argparse.Namespace) -> dict[str, Any]:
    """The config with the command line's overrides, checked (ValueError saying what is
    wrong): the run's numbers, the callbacks, the curriculum and a --trained-agent."""
    default = CONFIG_DIR / DEFAULT_CONFIG.get(args.algo, f"{args.algo}.yml")
    config = load_config(args.config or default)
    if args.n_timesteps is not None:
        config["n_timesteps"] = args.n_timesteps
    if args.n_envs is not None:
        config["n_envs"] = args.n_envs
    if args.max_episode_steps is not None:
        config.setdefault("env_kwargs", {})
        config["env_kwargs"] = {**(config["env_kwargs"] or {}),
                                "max_episode_steps": args.max_episode_steps}  # fmt: skip
        config.pop("max_episode_steps", None)
    check_config(config)
    if args.trained_agent is not None:
        check_trained_agent(args.trained_agent, args.algo, config, args.new_base_options)
    return config


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parse_cli(parser, argv)
    if args.new_base_options and args.trained_agent is None:
        parser.error(
            "--new-base-options changes the base of a trained agent: give the "
            "agent with --trained-agent (a new run takes the config's base as is)"
        )
    try:  # every check that needs no env, before the run directory is made
        config = _resolved_config(args)
    except (ValueError, OSError) as exc:  # UntrustedModelError is a ValueError
        parser.error(str(exc))
    check_dir_option(parser, "out", args.out)
    run = fresh_dir(args.out / f"{args.algo}_s{args.seed}")  # never overwrites a run
    train(args.algo, config, run, seed=args.seed, vec_env=args.vec_env,
          max_wall_seconds=args.max_wall_seconds, progress_bar=not args.no_progress,
          verbose=args.verbose, trained_agent=args.trained_agent,
          new_base_options=args.new_base_options)  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
