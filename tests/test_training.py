"""Training and evaluation: a tiny seeded PPO run is deterministic, and evaluate runs on
one held-out target with the pretrained models and writes the table.

Training runs on the small rod of tests/smallrod.py (SMALL); evaluation needs the
default physics (the pretrained models' observation statistics) but only a few steps.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from policies import PRETRAINED_DIR, load_policy
from tests.smallrod import SMALL, play, tiny_config

RESULTS = Path(__file__).resolve().parents[1] / "training" / "results"
#: goes on training the shipped agent (cnt-train --trained-agent) on the calibrated surrogate
SHIPPED_FINETUNE = "ppo_residual_shipped_detour_finetune.yml"
#: second stages over the shipped agent's base: the calibrated surrogate, detours 3 in 10
SECOND_STAGES = (SHIPPED_FINETUNE, "ppo_residual_difficulty_range_stage2.yml",
                 "ppo_residual_start_mirror_finetune.yml",
                 "ppo_residual_detour_mirror_finetune.yml",
                 "ppo_residual_detour_symgate_finetune.yml",
                 "ppo_lstm_residual_detour_finetune.yml")  # fmt: skip
# second stages whose flow gain is drawn per episode (evaluated on the calibrated surrogate)
GAINRAND_SECOND_STAGES = (
    "ppo_lstm_residual_gainrand_detour_finetune.yml",
    "ppo_residual_gainrand_detour_finetune.yml",
)


# warm states in a temporary cache, whatever a test forgets to pass (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("temp_warm_cache")


def _actions(model_path: Path) -> np.ndarray:
    return np.array(play(load_policy(model_path), 3, 8)[1])


def test_tiny_ppo_run_is_deterministic(tmp_path: Path) -> None:
    from training.train import train

    paths = [
        train("ppo", tiny_config(), tmp_path / f"run{i}", seed=seed, progress_bar=False)
        for i, seed in enumerate((7, 7, 8))
    ]
    for p in paths:
        assert p.is_file() and p.with_name("ppo_vecnormalize.pkl").is_file()
        assert (p.parent / "config.yml").is_file()
    a, b, c = (_actions(p) for p in paths)
    assert np.array_equal(a, b), "same seed must give the same actions"
    assert not np.array_equal(a, c), "another seed should give other actions"
    assert np.all(np.abs(a) <= 1.0)


@pytest.mark.parametrize("obs_mode", ["image", "dict"])
def test_a_tiny_cnn_run_is_deterministic(tmp_path: Path, obs_mode: str) -> None:
    """The CNN policies (image, dict) train to the same weights, bit for bit, from the
    same seed, and to other weights from another (torch on the CPU, one thread)."""
    from policies.sb3 import algo_class
    from training.train import train

    policy = {"image": "CnnPolicy", "dict": "MultiInputPolicy"}[obs_mode]
    extractor = {"image": {"features_dim": 16}, "dict": {"cnn_output_dim": 16}}[obs_mode]
    kwargs = {"net_arch": [16], "features_extractor_kwargs": extractor}
    config = {**tiny_config(), "n_timesteps": 64, "policy": policy, "normalize": True,
              "env_kwargs": {**SMALL, "obs_mode": obs_mode}, "policy_kwargs": kwargs}  # fmt: skip
    weights = []
    for i, seed in enumerate((7, 7, 8)):
        path = train("ppo", config, tmp_path / f"run{i}", seed=seed, progress_bar=False)
        params = algo_class("ppo").load(str(path), device="cpu").policy.state_dict()
        weights.append({k: v.numpy().copy() for k, v in params.items()})
    same = [all(np.array_equal(w[k], weights[0][k]) for k in w) for w in weights[1:]]
    assert same == [True, False]


@pytest.mark.skipif(not (PRETRAINED_DIR / "ppo.zip").is_file(), reason="no pretrained models")
def test_evaluate_one_route_with_pretrained_models(tmp_path: Path) -> None:
    """Every policy, with the pretrained models on the env settings they were trained on
    and the committed constant-flow choice, on one held-out route (a few steps)."""
    from training.common import load_config
    from training.evaluate import ALL_POLICIES, evaluate

    config = load_config(PRETRAINED_DIR / "ppo.yml")
    config["env_kwargs"]["max_episode_steps"] = 4
    table = evaluate(list(ALL_POLICIES), ["u_turn"], [0, 1, 2], config, tmp_path,
                     constant_from=RESULTS / "constant_best.json", jobs=2)  # fmt: skip
    overall = {r["policy"]: r for r in table if r["target"] == "ALL"}
    assert set(overall) == set(ALL_POLICIES)
    assert overall["random"]["normalized_score"] == pytest.approx(0.0)
    with (tmp_path / "results.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert {r["policy"] for r in rows} == set(ALL_POLICIES)
    assert {"score_mean", "score_std", "coverage_mean", "normalized_score"} <= set(rows[0])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert set(summary) == {"policies", "targets", "seeds", "custom_routes", "env_kwargs",
                            "max_episode_steps", "models", "model_sha256"}  # fmt: skip
    assert summary["custom_routes"] == {}
    # what the episodes ran on: the config's physics (here the surrogate) and models
    assert summary["env_kwargs"]["drag_law"] == config["env_kwargs"]["drag_law"] == "printed"
    assert summary["max_episode_steps"] == 4
    sac = Path(summary["models"]["sac"])  # relative to the working directory when under it
    assert sac.resolve() == (PRETRAINED_DIR / "sac.zip").resolve()
    assert set(summary["models"]) == {"ppo", "sac"}
    assert summary["targets"] == ["u_turn"] and summary["seeds"] == [0, 1, 2]
    for p in ALL_POLICIES:
        s = summary["policies"][p]
        assert set(s) == {"score_mean", "score_std"} and 0.0 <= s["score_mean"] <= 1.0
    assert (tmp_path / "traces_u_turn.png").is_file()


@pytest.mark.skipif(not (PRETRAINED_DIR / "ppo.zip").is_file(), reason="no pretrained models")
def test_evaluate_plays_an_ensemble_named_a_plus_b(tmp_path: Path) -> None:
    """``a+b`` is the mean of models a and b: an agent with itself lays the agent's own
    traces bit for bit; with another agent, other traces; a member that is no model is
    refused before any episode."""
    from training.common import load_config
    from training.evaluate import evaluate

    config = load_config(PRETRAINED_DIR / "ppo_residual.yml")
    config["env_kwargs"]["max_episode_steps"] = 4
    names = ["ppo_residual", "ppo_residual+ppo_residual", "ppo_residual+ppo"]
    evaluate(names, ["u_turn"], [0], config, tmp_path, jobs=1)
    rows = json.loads((tmp_path / "episodes.json").read_text())
    traces = np.load(tmp_path / "traces.npz")
    by = {r["policy"]: traces[f"trace_{i}"] for i, r in enumerate(rows)}
    np.testing.assert_array_equal(by["ppo_residual"], by["ppo_residual+ppo_residual"])
    assert not np.array_equal(by["ppo_residual"], by["ppo_residual+ppo"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["models"]["ppo_residual+ppo"].count(".zip") == 2
    with pytest.raises(FileNotFoundError, match="no nothing model"):
        evaluate(["ppo+nothing"], ["u_turn"], [0], config, tmp_path / "x", jobs=1)


@pytest.mark.skipif(not (PRETRAINED_DIR / "ppo.zip").is_file(), reason="no pretrained models")
def test_evaluate_takes_a_model_by_path_under_its_own_name(tmp_path: Path) -> None:
    """``model_paths`` (cnt-demo's short run): a policy name whose model is not
    ``<models>/<name>.zip`` plays that model, episode for episode as under its own name."""
    from training.common import load_config
    from training.evaluate import evaluate

    config = load_config(PRETRAINED_DIR / "ppo.yml")
    config["env_kwargs"]["max_episode_steps"] = 4
    by_dir = evaluate(["ppo"], ["u_turn"], [0, 1], config, tmp_path / "a", jobs=1)
    by_path = evaluate(
        ["short"],
        ["u_turn"],
        [0, 1],
        config,
        tmp_path / "b",
        jobs=1,
        models=tmp_path / "empty",
        model_paths={"short": PRETRAINED_DIR / "ppo.zip"},
    )
    assert [r["policy"] for r in by_path] == ["short"] * len(by_path)
    assert [r["score_mean"] for r in by_path] == [r["score_mean"] for r in by_dir]
    with pytest.raises(FileNotFoundError, match="no short model"):
        evaluate(
            ["short"],
            ["u_turn"],
            [0],
            config,
            tmp_path / "c",
            jobs=1,
            models=tmp_path / "empty",
            model_paths={"short": tmp_path / "none.zip"},
        )


def test_demo_short_run_selects_on_validation_with_the_recipes_rollouts() -> None:
    """cnt-demo's short run keeps the recipe's rollouts and learning settings, evaluates
    once per update, and chooses best_model.zip on validation routes only: never on a
    held-out route that the demo then scores (it chose on ``u_turn`` before 2026-12-07).
    Its length is a number of samples, so that one machine gives one model."""
    from training.common import (
        CHECKPOINT_CALLBACK,
        CONFIG_DIR,
        EVAL_CALLBACK,
        VALIDATION,
        held_out_names,
        load_config,
    )
    from training.demo import DEMO_CONFIG, SHORT_RUN_STEPS, short_run_config

    recipe = load_config(CONFIG_DIR / DEMO_CONFIG)
    cfg = short_run_config(recipe)
    own = ("callback", "n_timesteps")
    assert {k: v for k, v in cfg.items() if k not in own} == {
        k: v for k, v in recipe.items() if k not in own
    }
    (ev,) = [c[EVAL_CALLBACK] for c in cfg["callback"] if EVAL_CALLBACK in c]
    assert ev["eval_targets"] == [VALIDATION]
    assert not set(ev["eval_targets"]) & set(held_out_names({}))
    assert ev["eval_freq"] == recipe["n_steps"] * recipe["n_envs"]
    (ck,) = [c[CHECKPOINT_CALLBACK] for c in cfg["callback"] if CHECKPOINT_CALLBACK in c]
    assert ck["save_freq"] == 2 * ev["eval_freq"]
    # a sample budget of whole updates (not wall time), so a machine gives one model
    assert cfg["n_timesteps"] == SHORT_RUN_STEPS
    assert SHORT_RUN_STEPS % ev["eval_freq"] == 0 and SHORT_RUN_STEPS // ev["eval_freq"] >= 4
    assert short_run_config(recipe, 1024)["n_timesteps"] == 1024


@pytest.mark.parametrize("module", ["training.train", "training.evaluate", "training.demo"])
def test_a_file_given_as_the_output_directory_is_a_usage_error(
    module: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:  # fmt: skip
    """``--out`` naming an existing file: exit 2 with the reason, the file untouched (it
    was a NotADirectoryError or FileExistsError traceback)."""
    import importlib

    f = tmp_path / "trace.npz"
    f.write_bytes(b"data")
    argv = ["--algo", "ppo"] if module == "training.train" else []
    with pytest.raises(SystemExit) as exc:
        importlib.import_module(module).main([*argv, "--out", str(f)])
    assert exc.value.code == 2
    assert "is a file; give a directory" in capsys.readouterr().err
    assert f.read_bytes() == b"data" and list(tmp_path.iterdir()) == [f]


@pytest.mark.parametrize("bad", [True, 2.9, "300", 0, -3, None])
def test_the_episode_cap_must_be_a_positive_integer_as_written(bad) -> None:
    """``env_kwargs.max_episode_steps`` is checked before any conversion: true, 2.9 or
    "300" are mistakes in a YAML file, not 1, 2 or 300 (int() had accepted them)."""
    from training.common import check_run_config, env_settings

    config = {"n_timesteps": 10, "env_kwargs": {"max_episode_steps": bad}}
    if bad is None:  # absent: the default cap
        assert env_settings(config)[1] > 0
        return
    for check in (env_settings, check_run_config):
        with pytest.raises(ValueError, match="max_episode_steps must be a positive integer"):
            check(config)


def test_route_task_run_with_zoo_conventions(tmp_path: Path) -> None:
    """rl-zoo config forms (normalize: true, lin_ schedule, string policy_kwargs,
    max_episode_steps under env_kwargs, callbacks, a curriculum), best_model.zip, VecNormalize as
    npz + JSON read back, task metrics in tensorboard, and no overwritten run."""
    from training.common import fresh_dir
    from training.train import train

    env_kwargs = {k: v for k, v in SMALL.items()}
    config = {
        "n_timesteps": 128, "policy": "MlpPolicy", "n_envs": 1, "vec_env": "dummy",
        "normalize": True, "env_kwargs": {**env_kwargs, "max_episode_steps": 16},
        "callback": [{"training.callbacks.HeldOutEval": {"eval_targets": ["u_turn"],
                                                         "eval_freq": 64,
                                                         "n_eval_episodes": 1}},
                     {"training.callbacks.Curriculum": {"stages": [
                         {"at": 0.5, "families": ["straight"]}]}}],
        "n_steps": 32, "batch_size": 16, "n_epochs": 1, "learning_rate": "lin_3e-4",
        "policy_kwargs": "dict(net_arch=[8, 8])",
    }  # fmt: skip
    run = fresh_dir(tmp_path / "ppo_s0")
    model = train("ppo", config, run, seed=0, progress_bar=False)
    assert (run / "best_model.zip").is_file() and (run / "evaluations.npz").is_file()
    best = load_policy(run / "best_model.zip", algo="ppo")  # with its own statistics
    assert type(best.vecnormalize).__name__ == "NormalizerStats"
    for suffix in (".npz", ".json", ".pkl"):
        assert model.with_name(f"ppo_vecnormalize{suffix}").is_file()
    policy = load_policy(model)
    assert type(policy.vecnormalize).__name__ == "NormalizerStats"
    import pickle

    with model.with_name("ppo_vecnormalize.pkl").open("rb") as fh:
        vn = pickle.load(fh)
    assert np.array_equal(policy.vecnormalize.obs_rms.mean, vn.obs_rms.mean)
    obs = np.linspace(-3, 3, vn.obs_rms.mean.size).astype(np.float32)[None]
    assert np.allclose(policy.vecnormalize.normalize_obs(obs), vn.normalize_obs(obs))
    events = b"".join(p.read_bytes() for p in (run / "tb").rglob("events.out.tfevents*"))
    assert b"task/score" in events and b"task/progress" in events
    assert b"curriculum/stage" in events
    again = fresh_dir(tmp_path / "ppo_s0")
    assert again != run and again.name == "ppo_s0_2"


def test_evaluate_routes_with_the_follower(tmp_path: Path) -> None:
    from training.evaluate import evaluate

    config = {"env_kwargs": {**SMALL, "max_episode_steps": 3}}
    table = evaluate(["random", "scripted"], ["u_turn"], [0, 1], config, tmp_path, jobs=2)
    overall = {r["policy"]: r for r in table if r["target"] == "ALL"}
    assert set(overall) == {"random", "scripted"}
    for r in overall.values():
        assert 0.0 <= r["score_mean"] <= 1.0


def test_csv_columns_are_every_key_and_a_reused_row_may_lack_the_newer(tmp_path) -> None:
    from training.evaluate import _write_csv

    _write_csv(tmp_path / "t.csv", [{"a": 1, "b": 0.5}, {"a": 2, "b": 1.0, "c": True}])
    with (tmp_path / "t.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["a", "b", "c"]
    assert rows == [{"a": "1", "b": "0.5", "c": ""}, {"a": "2", "b": "1", "c": "True"}]


def test_evaluate_on_routes_of_a_route_file(tmp_path: Path) -> None:
    """cnt-evaluate --route-file: every baseline, the constant-flow oracle included, on a
    user's own route, with the route's corridor and keep-out, next to a held-out one."""
    from training.evaluate import main

    route = {"name": "my_jog", "waypoints": [[0, 0], [30, 0], [30, 25]], "width": 14.0,
             "keepouts": [{"rect": [40, -5, 50, 5]}]}  # fmt: skip
    (tmp_path / "routes.json").write_text(json.dumps([route]))
    (tmp_path / "small.yml").write_text(
        "CNTDeposit-v0:\n  env_kwargs: " + json.dumps({**SMALL, "max_episode_steps": 3}) + "\n"
    )
    out = tmp_path / "out"
    assert main(["--policies", "random,constant,scripted", "--route-file",
                 str(tmp_path / "routes.json"), "--targets", "my_jog,u_turn", "--seeds", "0",
                 "--config", str(tmp_path / "small.yml"), "--jobs", "2",
                 "--out", str(out)]) == 0  # fmt: skip
    summary = json.loads((out / "summary.json").read_text())
    assert summary["targets"] == ["my_jog", "u_turn"]
    assert list(summary["custom_routes"]) == ["my_jog"]
    assert summary["custom_routes"]["my_jog"]["width"] == 14.0
    with (out / "episodes.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert {(r["policy"], r["target"]) for r in rows} == {
        (p, t) for p in ("random", "constant", "scripted") for t in ("my_jog", "u_turn")
    }
    # what is_success asks of a route is in the row: no pads on either route, and no
    # short, since 3 steps of the small rod lay ~1 L_vb and the keep-out starts at x = 40
    for r in rows:
        assert r["n_pads"] == "0" and r["pads_crossed"] == "0"
        assert float(r["short_length"]) == 0.0
    best = json.loads((out / "constant_best.json").read_text())["best"]
    assert set(best) == {"my_jog", "u_turn"}
    assert (out / "traces_my_jog.png").is_file()


def test_reuse_takes_a_file_route_s_episodes_only_for_the_same_route(tmp_path: Path) -> None:
    """--reuse with --route-file: episodes of a name are reused only where the earlier run
    evaluated the same route under it (its summary.json), never a route of the same name
    with other waypoints."""
    from cnt_env.task import routes
    from training.evaluate import evaluate

    config = {"env_kwargs": {**SMALL, "max_episode_steps": 2}}
    jog = routes.from_dict({"name": "jog", "waypoints": [[0, 0], [30, 0], [30, 20]]})
    other = routes.from_dict({"name": "jog", "waypoints": [[0, 0], [0, 40]]})
    first = tmp_path / "first"
    evaluate(["random"], ["jog"], [0], config, first, jobs=1, custom_routes={"jog": jog})
    saved = json.loads((first / "episodes.json").read_text())
    (first / "episodes.json").write_text(json.dumps([{**r, "wall_s": -1.0} for r in saved]))

    def wall(route: routes.Route) -> float:
        out = tmp_path / f"again_{len(route.waypoints)}"
        evaluate(["random"], ["jog"], [0], config, out, jobs=1, reuse=[first],
                 custom_routes={"jog": route})  # fmt: skip
        with (out / "episodes.csv").open() as fh:
            return float(next(csv.DictReader(fh))["wall_s"])

    assert wall(jog) == -1.0  # the same route: reused
    assert wall(other) >= 0.0  # another route under the same name: run again


def test_reuse_carries_only_the_asked_episodes_and_the_first_directory_wins(
    tmp_path: Path,
) -> None:
    """--reuse keeps, of a results dir, only the episodes of the asked targets and seeds
    (a dir of seeds 0-1 reused for seed 1 carries seed 1 alone), each from the first dir
    that has it."""
    from training.evaluate import evaluate

    config = {"env_kwargs": {**SMALL, "max_episode_steps": 2}}
    dirs = []
    for tag in (-1.0, -2.0):
        d = tmp_path / f"dir{len(dirs)}"
        evaluate(["random"], ["u_turn"], [0, 1], config, d, jobs=1)
        saved = json.loads((d / "episodes.json").read_text())
        (d / "episodes.json").write_text(json.dumps([{**r, "wall_s": tag} for r in saved]))
        dirs.append(d)
    out = tmp_path / "again"
    evaluate(["random"], ["u_turn"], [1], config, out, jobs=1, reuse=dirs)
    rows = json.loads((out / "episodes.json").read_text())
    assert [(r["seed"], r["wall_s"]) for r in rows] == [(1, -1.0)]


def test_episode_frame_is_relative_to_the_contact_at_reset() -> None:
    """The results' frame: the trace from the contact point at reset, and the route (which
    starts there), both shifted so that point is the origin."""
    from training.common import make_env
    from training.evaluate import episode_frame

    env = make_env(dict(SMALL), 3)
    env.reset(seed=0, options={"target": "u_turn"})
    for _ in range(2):
        env.step(np.array([0.5, 0.0], dtype=np.float32))
    base = env.unwrapped
    trace, target = episode_frame(base)
    full = base.sim.trace()
    # the route starts at the contact point, which lies within a node's motion of the
    # last deposited node
    assert np.array_equal(trace[0], [0.0, 0.0]) and np.allclose(target[0], 0.0, atol=1e-3)
    assert len(trace) == len(full) - base.episode_start + 1 > 2
    shift = full[base.episode_start - 1, [0, 2]]
    assert np.array_equal(trace[-1], full[-1, [0, 2]] - shift)
    assert np.allclose(target + shift, base.target_path)
    env.close()


def test_evaluate_reuses_episodes_and_redoes_a_changed_baseline(tmp_path: Path) -> None:
    """--reuse keeps a fully evaluated policy's episodes (the same rows, not re-run);
    --redo runs a policy again even though the reused results have it."""
    from training.evaluate import evaluate

    config = {"env_kwargs": {**SMALL, "max_episode_steps": 2}}
    first = tmp_path / "first"
    evaluate(["random", "scripted"], ["u_turn"], [0], config, first, jobs=1)
    # mark the saved episodes: a reused row keeps the mark, a re-run one has a real time
    saved = json.loads((first / "episodes.json").read_text())
    (first / "episodes.json").write_text(json.dumps([{**r, "wall_s": -1.0} for r in saved]))

    def wall(out: Path, **kw) -> dict[str, float]:
        evaluate(["random", "scripted"], ["u_turn"], [0], config, out, jobs=1,
                 reuse=[first], **kw)  # fmt: skip
        with (out / "episodes.csv").open() as fh:
            return {r["policy"]: float(r["wall_s"]) for r in csv.DictReader(fh)}

    assert wall(tmp_path / "kept") == {"random": -1.0, "scripted": -1.0}
    redone = wall(tmp_path / "redone", redo=["scripted"])
    assert redone["random"] == -1.0 and redone["scripted"] >= 0.0


def test_reuse_takes_a_trained_policys_episodes_only_from_the_same_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """summary.json records each trained policy's model sha256; --reuse takes a trained
    policy's episodes only where the recorded model is the one given now (the same name
    may be another model), and says so where an older run recorded none."""
    from training.common import load_config
    from training.evaluate import evaluate

    config = load_config(PRETRAINED_DIR / "ppo.yml")
    config["env_kwargs"]["max_episode_steps"] = 2
    first = tmp_path / "first"

    def run(out: Path, model: str, **kw) -> float:
        evaluate(["agent"], ["u_turn"], [0], config, out, jobs=1, models=tmp_path / "none",
                 model_paths={"agent": PRETRAINED_DIR / model}, **kw)  # fmt: skip
        with (out / "episodes.csv").open() as fh:
            return float(next(csv.DictReader(fh))["wall_s"])

    run(first, "ppo.zip")
    summary = json.loads((first / "summary.json").read_text())
    from policies.sb3 import file_sha256

    assert summary["model_sha256"] == {"agent": [file_sha256(PRETRAINED_DIR / "ppo.zip")]}
    saved = json.loads((first / "episodes.json").read_text())
    (first / "episodes.json").write_text(json.dumps([{**r, "wall_s": -1.0} for r in saved]))
    assert run(tmp_path / "same", "ppo.zip", reuse=[first]) == -1.0  # reused
    assert run(tmp_path / "other", "sac.zip", reuse=[first]) >= 0.0  # played again
    assert "not reused from" in capsys.readouterr().out
    del summary["model_sha256"]  # a run made before the hashes were recorded
    (first / "summary.json").write_text(json.dumps(summary))
    assert run(tmp_path / "legacy", "sac.zip", reuse=[first]) == -1.0
    assert "records no sha256" in capsys.readouterr().out
    legacy = json.loads((tmp_path / "legacy" / "summary.json").read_text())
    assert legacy["model_sha256"] == {}  # not certified by this run


def test_evaluate_into_a_used_out_names_the_files_it_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An --out holding an earlier evaluation keeps the files this one does not write
    (a --reuse run relies on that for learning_curves.png): they are listed, so a stale
    figure is not taken for a new one; the files it writes again are not."""
    from training.evaluate import evaluate

    config = {"env_kwargs": {**SMALL, "max_episode_steps": 2}}
    out = tmp_path / "out"
    evaluate(["random"], ["u_turn"], [0], config, out, jobs=1)
    capsys.readouterr()
    evaluate(["random"], ["l_up"], [0], config, out, jobs=1)
    kept = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("kept in")]
    assert len(kept) == 1 and kept[0].endswith("traces_u_turn.png"), kept
    assert (out / "traces_l_up.png").is_file()


def test_evaluate_names_recordings_and_videos_after_their_episodes(tmp_path: Path) -> None:
    """--save-episodes, --rrd and --video name one episode alike (its recording id,
    ``<policy>-<target>-s<seed>-e0000``), so each recording or video finds its episode."""
    pytest.importorskip("rerun")
    pytest.importorskip("imageio_ffmpeg")
    from training.evaluate import evaluate

    config = {"env_kwargs": {**SMALL, "max_episode_steps": 2}}
    evaluate(["random"], ["u_turn"], [0, 1], config, tmp_path / "out", jobs=1,
             save_episodes=tmp_path / "ep", rrd=tmp_path / "rrd", video=tmp_path / "vid",
             video_format="gif")  # fmt: skip
    episodes = sorted(p.stem for p in (tmp_path / "ep").glob("*.npz"))
    assert episodes == ["random-u_turn-s0-e0000", "random-u_turn-s1-e0000"]
    assert sorted(p.stem for p in (tmp_path / "vid").glob("*.gif")) == episodes
    assert [p.stem for p in (tmp_path / "rrd").glob("*.rrd")] == episodes[:1]  # first seed


def test_validation_eval_routes_are_fixed_family_draws() -> None:
    """``validation`` eval targets are routes drawn from the families with fixed seeds:
    distinct slots give distinct routes, every pass over the list repeats them, and none
    is a held-out route."""
    import gymnasium as gym

    from training.common import ENV_ID, VALIDATION, HeldOutCycle, held_out_names

    env = HeldOutCycle(gym.make(ENV_ID, **SMALL), [VALIDATION, VALIDATION, "u_turn"])
    names, points = [], []
    for _ in range(6):
        env.reset()
        t = env.unwrapped.target
        names.append(t.name)
        points.append(np.asarray(t.points).copy())
    env.close()
    assert names[2] == names[5] == "u_turn"
    assert not np.array_equal(points[0], points[1]) or names[0] != names[1]
    np.testing.assert_array_equal(points[0], points[3])
    np.testing.assert_array_equal(points[1], points[4])
    held = set(held_out_names({}))
    assert names[0] not in held and names[1] not in held
    with pytest.raises(ValueError, match="validation"):
        HeldOutCycle(gym.make(ENV_ID, **SMALL), ["nope"])


def test_learning_curve_panels_part_runs_trained_on_different_envs(tmp_path: Path) -> None:
    """Two stages of one agent on different envs (the shipped residual agent: the
    surrogate, then the calibrated surrogate with detours weighted) get a panel each, so
    each has the baselines of its own env; runs on the same env share one."""
    import yaml

    from training.evaluate import curve_groups

    ev = [{"training.callbacks.HeldOutEval": {"eval_targets": ["validation"],
                                               "n_eval_episodes": 1}}]  # fmt: skip
    envs = {"a": {"drag_law": "printed", "delta_bar": 1.0},
            "b": {"drag_law": "printed", "delta_bar": 1.0},
            "c": {"drag_law": "printed", "delta_bar": 1.0, "flow_gain": 1.44,
                  "families": ["straight", "detour", "detour"]}}  # fmt: skip
    runs = []
    for name, kw in envs.items():
        run = tmp_path / name
        run.mkdir()
        cfg = {"CNTDeposit-v0": {"env_kwargs": kw, "callback": ev}}
        (run / "config.yml").write_text(yaml.safe_dump(cfg))
        np.savez(run / "evaluations.npz", timesteps=np.array([1]), results=np.array([[0.5]]))
        runs.append(run)
    groups = curve_groups(runs)
    assert sorted(len(v) for v in groups.values()) == [1, 2]
    labels = sorted(k[1] for k in groups)
    assert labels == ["printed law, δ̄ 1", "printed law, δ̄ 1, flow x1.44, detour 2 in 3"]


def test_runs_on_other_observations_share_a_panel_and_are_labelled_apart(
    tmp_path: Path,
) -> None:
    """PPO on the vector, the image and the Dict (the same env, so one panel with one set
    of baselines) are told apart by their labels; the vector run keeps its plain one."""
    import yaml

    from training.evaluate import curve_groups

    ev = [{"training.callbacks.HeldOutEval": {"eval_targets": ["validation"],
                                               "n_eval_episodes": 1}}]  # fmt: skip
    runs = []
    for mode in ("vector", "image", "dict"):
        run = tmp_path / f"ppo_{mode}"
        run.mkdir()
        kw = {"drag_law": "printed", "delta_bar": 1.0} | (
            {} if mode == "vector" else {"obs_mode": mode}
        )
        cfg = {"CNTDeposit-v0": {"env_kwargs": kw, "callback": ev},
               "run": {"algo": "ppo", "seed": 0}}  # fmt: skip
        (run / "config.yml").write_text(yaml.safe_dump(cfg))
        np.savez(run / "evaluations.npz", timesteps=np.array([1]), results=np.array([[0.5]]))
        runs.append(run)
    (curves,) = curve_groups(runs).values()
    assert [c[2] for c in curves] == ["ppo s0", "ppo s0 [image]", "ppo s0 [dict]"]


def test_eval_env_kwargs_override_the_training_env_for_evaluation_only() -> None:
    """HeldOutEval's env_kwargs: the evaluation env is the training env with them over it
    (a fixed flow gain where training draws one per episode); without them, the same env.
    The curve label names the evaluation env, whose baselines the curve is drawn with."""
    from training.common import env_settings, eval_env_settings
    from training.evaluate import _env_label

    train_kw = {"drag_law": "printed", "delta_bar": 1.0, "flow_gain": [1.0, 2.0],
                "max_episode_steps": 300}  # fmt: skip
    ev = {"eval_targets": ["validation"], "env_kwargs": {"flow_gain": 1.44}}
    cfg = {"env_kwargs": train_kw, "callback": [{"training.callbacks.HeldOutEval": ev}]}
    assert env_settings(cfg)[0]["flow_gain"] == [1.0, 2.0]
    assert eval_env_settings(cfg) == ({"drag_law": "printed", "delta_bar": 1.0,
                                       "flow_gain": 1.44}, 300)  # fmt: skip
    assert _env_label(cfg) == "printed law, δ̄ 1, flow x1.44"
    del ev["env_kwargs"]
    assert eval_env_settings(cfg) == env_settings(cfg)
    assert _env_label(cfg) == "printed law, δ̄ 1, flow x1-2"
    ev["env_kwargs"] = {"max_episode_steps": 10}
    with pytest.raises(ValueError, match="max_episode_steps"):
        eval_env_settings(cfg)


def test_learning_curves_on_validation_routes_get_their_own_baselines(tmp_path: Path) -> None:
    """A run evaluated on validation routes is drawn with the follower and random scored
    on those same routes, not with held-out rows; cnt-evaluate caches them in its own
    output (the run may be a committed result), a direct call in the run."""
    import yaml

    from training.evaluate import eval_set_baselines, plot_learning_curves

    run = tmp_path / "ppo_residual_s0"
    run.mkdir()
    cfg = {"env_kwargs": {**SMALL, "max_episode_steps": 2},
           "callback": [{"training.callbacks.HeldOutEval": {
               "eval_targets": ["validation", "validation"], "eval_freq": 10,
               "n_eval_episodes": 2}}]}  # fmt: skip
    meta = {"timesteps_done": 20, "wall_time_s": 120.0}
    (run / "config.yml").write_text(yaml.safe_dump({"CNTDeposit-v0": cfg, "run": meta}))
    np.savez(run / "evaluations.npz", timesteps=np.array([10, 20]),
             results=np.array([[0.1, 0.2], [0.3, 0.4]]))  # fmt: skip
    out = tmp_path / "out"
    out.mkdir()
    assert plot_learning_curves([run], out, rows=[])
    assert (out / "learning_curves.png").is_file()
    assert sorted(p.name for p in run.iterdir()) == ["config.yml", "evaluations.npz"]
    mine = out / "eval_baselines_ppo_residual_s0.json"
    cached = json.loads(mine.read_text())
    assert cached["eval_targets"] == ["validation", "validation"] and cached["n"] == 2
    assert set(cached["scores"]) == {"scripted", "random"}
    assert all(0.0 <= v <= 1.0 for v in cached["scores"].values())
    # the cache is what a second call reads, from the output or from the run
    cached["scores"] = {"scripted": 0.5, "random": 0.25}
    mine.write_text(json.dumps(cached))
    assert eval_set_baselines(run, cache_dir=out) == {"scripted": 0.5, "random": 0.25}
    mine.unlink()
    (run / "eval_baselines.json").write_text(json.dumps(cached))
    assert eval_set_baselines(run) == {"scripted": 0.5, "random": 0.25}
    # ... unless the baselines' code changed since (a follower improved): scored again
    (run / "eval_baselines.json").write_text(json.dumps({**cached, "code": "older"}))
    assert eval_set_baselines(run) != {"scripted": 0.5, "random": 0.25}


def test_tables_without_random_say_why_there_is_no_normalised_score() -> None:
    from training.evaluate import NO_FLOOR, _format_table, aggregate, markdown_tables

    rows = [{"policy": "scripted", "target": "u_turn", "seed": s, "score": 0.9,
             "coverage": 1.0, "precision": 0.9, "progress": 1.0, "mean_distance": 3.0,
             "is_success": True}
            for s in (0, 1)]  # fmt: skip
    table = aggregate(rows, ["scripted"], ["u_turn"], [0, 1])
    md, text = markdown_tables(table), _format_table(table)
    assert "nan" not in md and "nan" not in text
    assert "| n/a |" in md and NO_FLOOR in md and NO_FLOOR in text


def test_baseline_cache_key_follows_the_simulator(monkeypatch: pytest.MonkeyPatch) -> None:
    """A cached follower score is stale when the simulator changes, not only when the
    follower does (a solver change once left a stale score behind)."""
    from cnt_env.sim import warmstart
    from training import evaluate

    before = evaluate._baselines_code()
    monkeypatch.setattr(warmstart, "source_fingerprint", lambda: "another simulator")
    assert evaluate._baselines_code() != before


def test_a_run_pins_the_physics_its_envs_ran_where_the_config_left_the_default(
    tmp_path: Path,
) -> None:
    """The run's config.yml and the model's .yml name the drag law and delta_bar the envs
    resolved: the env's defaults where the config gives none, the config's own where it
    does; the model then loads with the physics it trained on."""
    import gymnasium as gym
    import yaml

    from cnt_env.presets import MODEL
    from training.train import train

    runs = {
        "default": {**tiny_config(), "n_timesteps": 64},
        "printed": {**tiny_config(), "n_timesteps": 64,
                    "env_kwargs": {**SMALL, "drag_law": "printed", "delta_bar": 1.0}},
    }  # fmt: skip
    env = gym.make("CNTDeposit-v0", **SMALL)
    resolved = float(env.unwrapped.params.delta_bar)
    env.close()
    assert resolved != 1.0 and MODEL["drag_law"] != "printed"  # the two runs differ
    for name, config in runs.items():
        model = train("ppo", config, tmp_path / name, seed=0, progress_bar=False)
        for path in (model.with_suffix(".yml"), model.parent / "config.yml"):
            kw = yaml.safe_load(path.read_text())["CNTDeposit-v0"]["env_kwargs"]
            want = (MODEL["drag_law"], resolved) if name == "default" else ("printed", 1.0)
            assert (kw["drag_law"], kw["delta_bar"]) == want, (name, path.name)
            assert {k: kw[k] for k in SMALL} == SMALL  # the rest as given
    assert "drag_law" not in runs["default"]["env_kwargs"]  # the caller's config untouched


def test_a_residual_model_pins_its_base_options(tmp_path: Path) -> None:
    """A residual run writes every option of its base follower beside the model, and the
    model loads with them: a later change of the follower's defaults does not change the
    base a trained agent acts on. A config without them warns; an unknown option raises."""
    import gymnasium as gym
    import yaml

    from policies import RouteFollower
    from policies.base import policy_options
    from policies.residual import base_options
    from training.train import train

    config = {**tiny_config(), "n_timesteps": 64, "env_wrapper": [
        {"training.common.ResidualAction": {"base": "scripted", "scale": 0.3,
                                            "base_kwargs": {"lead": 0.0}}}]}  # fmt: skip
    model = train("ppo", config, tmp_path / "resid", seed=0, progress_bar=False)
    entry = yaml.safe_load(model.with_suffix(".yml").read_text())["CNTDeposit-v0"]
    pinned = entry["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]
    assert pinned == {**RouteFollower.OPTIONS, "lead": 0.0}
    env = gym.make("CNTDeposit-v0", **SMALL)
    policy = load_policy(model, env=env)
    assert isinstance(policy.base, RouteFollower) and policy_options(policy.base) == pinned

    # an unpinned config (written before pinning) gets today's defaults, with a warning
    del entry["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]
    model.with_suffix(".yml").write_text(yaml.safe_dump({"CNTDeposit-v0": entry}))
    from policies.sb3 import write_manifest

    listed = json.loads((model.parent / "MANIFEST.json").read_text())["sha256"]
    write_manifest(model.parent, list(listed))
    with pytest.warns(UserWarning, match="does not pin"):
        assert policy_options(load_policy(model, env=env).base) == RouteFollower.OPTIONS
    env.close()
    with pytest.raises(ValueError, match="unknown option"):
        base_options("scripted", "corridor", {"lookahaed": 10.0})


def test_a_config_pinned_before_an_option_existed_keeps_the_base_without_it() -> None:
    """Options the follower gained after pinning began (``RouteFollower.ADDED``) take
    their old value in a config that pins every other option (the shipped agent's), and
    today's default in a partial or absent one."""
    from policies import RouteFollower
    from policies.residual import base_options

    added = RouteFollower.ADDED
    assert added and set(added) <= set(RouteFollower.OPTIONS)
    old = {k: v for k, v in RouteFollower.OPTIONS.items() if k not in added}
    assert base_options("scripted", "corridor", old) == {**RouteFollower.OPTIONS, **added}
    # an option the old config pins itself wins over the legacy value
    some = next(iter(added))
    got = base_options("scripted", "corridor", {**old, some: RouteFollower.OPTIONS[some]})
    assert got[some] == RouteFollower.OPTIONS[some]
    assert base_options("scripted", "corridor", {"lead": 2.0}) == {**RouteFollower.OPTIONS,
                                                                    "lead": 2.0}  # fmt: skip
    assert base_options("scripted", "corridor", None) == RouteFollower.OPTIONS


def test_zoo_lists_read_and_pin_in_every_rl_zoo_form() -> None:
    """rl-zoo writes a wrapper as a bare name, a one-key dict, or a list of either; the
    residual settings are read from, and pinned into, each form; other entries survive."""
    from policies.residual import WRAPPER, pin_base, residual_settings, zoo_entry

    other = {"gymnasium.wrappers.TimeAwareObservation": None}
    kwargs = {"base": "scripted", "scale": 0.5}
    forms = [(WRAPPER, {}), ({WRAPPER: kwargs}, kwargs), ([other, WRAPPER], {}),
             ([other, {WRAPPER: kwargs}], kwargs)]  # fmt: skip
    for wrappers, expected in forms:
        entry = {"policy": "MlpPolicy", "env_wrapper": wrappers}
        assert residual_settings(entry) == expected
        pinned = pin_base(entry, "corridor")["env_wrapper"]
        assert [w for w in pinned if w is not other] == [
            {WRAPPER: {**expected, "base_kwargs": pinned[-1][WRAPPER]["base_kwargs"]}}
        ]
        assert pinned[-1][WRAPPER]["base_kwargs"]  # every option of the follower
        assert (other in pinned) == isinstance(wrappers, list)
    assert zoo_entry(None, WRAPPER) is None and zoo_entry([other], WRAPPER) is None
    assert pin_base({"policy": "MlpPolicy"}, "corridor") == {"policy": "MlpPolicy"}


def test_frame_stack_trains_and_loads_with_the_stack_sb3_builds(tmp_path: Path) -> None:
    """rl-zoo's ``frame_stack``: the model trains on SB3's VecFrameStack of normalised
    observations, and the loaded policy rebuilds the same stack step by step (zeros
    before the first observation, newest last), restarting at reset."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecFrameStack, VecNormalize

    from policies.sb3 import frame_stack
    from training.common import make_env
    from training.train import train

    model = train("ppo", {**tiny_config(), "n_timesteps": 64, "frame_stack": 3},
                  tmp_path / "stack", seed=0, progress_bar=False)  # fmt: skip
    policy = load_policy(model)
    assert policy.frame_stack == 3
    assert policy.model.observation_space.shape == (3 * policy.vecnormalize.obs_rms.mean.size,)

    venv = VecNormalize.load(str(model.with_name("ppo_vecnormalize.pkl")),
                             DummyVecEnv([lambda: make_env(SMALL, 30)]))  # fmt: skip
    venv.training, venv.norm_reward = False, False
    venv = VecFrameStack(venv, 3)
    for _episode in range(2):  # the stack restarts at reset
        venv.seed(3)
        stacked = venv.reset()
        obs = venv.venv.get_original_obs()[0]
        policy.reset(3)
        for _ in range(4):
            want, _ = policy.model.predict(stacked, deterministic=True)
            got = policy.act(obs)
            np.testing.assert_array_equal(got, np.asarray(want, np.float32).reshape(-1))
            stacked, *_ = venv.step(want)
            obs = venv.venv.get_original_obs()[0]
    venv.close()
    assert [frame_stack({}), frame_stack({"frame_stack": 0}), frame_stack({"frame_stack": 4})] == [
        1,
        1,
        4,
    ]
    for bad in (-1, 2.5, True, "4"):
        with pytest.raises(ValueError, match="frame_stack"):
            frame_stack({"frame_stack": bad})


def _acts_as_its_model(policy, env_kwargs: dict, model_input) -> None:
    """Over three steps of the small rod's "jog", ``policy.act(obs)`` is the model's
    deterministic action for ``model_input(obs)`` (what the model should be given)."""
    from training.common import make_env

    env = make_env(env_kwargs, 30)
    obs, _ = env.reset(seed=2, options={"target": "jog"})
    policy.reset(2)
    for _ in range(3):
        want, _ = policy.model.predict(model_input(obs), deterministic=True)
        got = policy.act(obs)
        np.testing.assert_array_equal(got, np.asarray(want, np.float32).reshape(-1))
        obs, *_ = env.step(got)
    env.close()


def test_an_image_policy_trains_on_raw_pixels_and_loads_with_its_reward_statistics(
    tmp_path: Path,
) -> None:
    """``obs_mode: image`` with ``normalize: true``: VecNormalize normalises the reward
    only (SB3's CnnPolicy takes the uint8 image and scales it itself; normalised floats
    fail its image check), the statistics save and load without observation arrays, and
    the loaded policy acts as the model does on the raw image. Asking to normalise the
    image is refused before anything is built."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from training.common import make_env, normalize_settings
    from training.train import train

    image_env = {**SMALL, "obs_mode": "image"}
    config = {**tiny_config(), "n_timesteps": 64, "policy": "CnnPolicy", "normalize": True,
              "env_kwargs": image_env,
              "policy_kwargs": {"net_arch": [16], "features_extractor_kwargs":
                                {"features_dim": 16}},
              "callback": [{"training.callbacks.HeldOutEval": {  # syncs the statistics
                  "eval_targets": ["u_turn"], "eval_freq": 32, "n_eval_episodes": 1}}]}  # fmt: skip
    assert normalize_settings(config, obs_mode="image") == {"norm_obs": False, "norm_reward": True}
    model = train("ppo", config, tmp_path / "cnn", seed=0, progress_bar=False)
    assert (tmp_path / "cnn" / "evaluations.npz").is_file()
    best = load_policy(tmp_path / "cnn" / "best_model.zip", algo="ppo")
    assert best.vecnormalize.norm_obs is False
    stats = model.with_name("ppo_vecnormalize")
    with np.load(stats.with_suffix(".npz")) as d:
        assert sorted(d.files) == ["ret_count", "ret_mean", "ret_var"]
    policy = load_policy(model)
    assert policy.vecnormalize.norm_obs is False
    _acts_as_its_model(policy, image_env, lambda obs: obs)
    # the pickle VecNormalize.load reads, and going on from the saved statistics
    venv = VecNormalize.load(str(stats.with_suffix(".pkl")),
                             DummyVecEnv([lambda: make_env(image_env, 30)]))  # fmt: skip
    assert venv.norm_obs is False
    from policies.sb3 import restore_vecnormalize

    restore_vecnormalize(venv, stats)
    venv.close()
    again = train("ppo", config, tmp_path / "cnn_again", seed=0, progress_bar=False,
                  trained_agent=model)  # fmt: skip
    assert again.is_file()
    # evaluated beside a vector baseline on the vector env's config: the model observes
    # the image it was trained on (its own config), the follower the vector
    from training.evaluate import evaluate

    vector = tiny_config()  # the config beside the model (ppo.yml) says obs_mode: image
    table = evaluate(["scripted", "cnn"], ["u_turn"], [0], vector, tmp_path / "eval",
                     jobs=1, models=tmp_path / "empty", model_paths={"cnn": model})  # fmt: skip
    assert {r["policy"] for r in table} >= {"scripted", "cnn"}
    from training.evaluate import eval_set_baselines  # the learning curve's baselines

    assert set(eval_set_baselines(tmp_path / "cnn")) == {"scripted", "random"}
    bad = {**config, "normalize": {"norm_obs": True}}
    with pytest.raises(ValueError, match="norm_obs on an image"):
        train("ppo", bad, tmp_path / "refused", seed=0, progress_bar=False)
    residual = {**config, "normalize": True, "env_wrapper": [
        {"training.common.ResidualAction": {"base": "scripted", "scale": 0.5}}]}  # fmt: skip
    with pytest.raises(ValueError, match="residual agent"):
        train("ppo", residual, tmp_path / "refused", seed=0, progress_bar=False)
    assert not (tmp_path / "refused").exists()


def test_a_dict_policy_normalises_the_vector_not_the_image_and_loads_safely(tmp_path) -> None:
    """obs_mode "dict" (MultiInputPolicy): normalize: true normalises the reward and the
    "vector" part only, the per-key statistics save, load (without unpickling the model)
    and restore, and the loaded policy acts as the model does on the normalised vector and
    the raw image. Normalising the image, a residual base or a frame stack is refused."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from policies.residual import combine
    from policies.sb3 import SB3Policy, restore_vecnormalize
    from training.common import make_env, normalize_settings
    from training.train import train

    dict_env = {**SMALL, "obs_mode": "dict"}
    config = {**tiny_config(), "n_timesteps": 64, "policy": "MultiInputPolicy",
              "normalize": True, "env_kwargs": dict_env,
              "policy_kwargs": {"net_arch": [16], "features_extractor_kwargs":
                                {"cnn_output_dim": 16}},
              "callback": [{"training.callbacks.HeldOutEval": {
                  "eval_targets": ["u_turn"], "eval_freq": 32, "n_eval_episodes": 1}}]}  # fmt: skip
    assert normalize_settings(config, obs_mode="dict") == {
        "norm_obs": True, "norm_obs_keys": ["vector"], "norm_reward": True}  # fmt: skip
    model = train("ppo", config, tmp_path / "multi", seed=0, progress_bar=False)
    assert (tmp_path / "multi" / "best_model.zip").is_file()
    stats = model.with_name("ppo_vecnormalize")
    with np.load(stats.with_suffix(".npz")) as d:
        assert sorted(d.files) == ["obs_count.vector", "obs_mean.vector", "obs_var.vector",
                                   "ret_count", "ret_mean", "ret_var"]  # fmt: skip
        n_vector = d["obs_mean.vector"].shape
    policy = load_policy(model)  # trust=False: the Dict space is rebuilt from its text
    assert set(policy.vecnormalize.obs_rms) == {"vector"}
    assert policy.vecnormalize.obs_rms["vector"].mean.shape == n_vector
    rms = policy.vecnormalize.obs_rms["vector"]

    def model_input(obs: dict) -> dict:  # VecNormalize's formula on the vector alone
        v = (obs["vector"] - rms.mean) / np.sqrt(rms.var + policy.vecnormalize.epsilon)
        clip = policy.vecnormalize.clip_obs
        return {"image": obs["image"][None], "vector": np.clip(v, -clip, clip)[None]}

    _acts_as_its_model(policy, dict_env, model_input)
    venv = VecNormalize.load(str(stats.with_suffix(".pkl")),
                             DummyVecEnv([lambda: make_env(dict_env, 30)]))  # fmt: skip
    before = venv.obs_rms["vector"].count
    venv.obs_rms["vector"].count = 1.0
    restore_vecnormalize(venv, stats)
    assert venv.obs_rms["vector"].count == before
    venv.close()
    again = train("ppo", config, tmp_path / "multi_again", seed=0, progress_bar=False,
                  trained_agent=model)  # fmt: skip
    assert again.is_file()
    from training.evaluate import evaluate  # beside the follower, each on its own view

    table = evaluate(["scripted", "multi"], ["u_turn"], [0], tiny_config(), tmp_path / "eval",
                     jobs=1, models=tmp_path / "empty", model_paths={"multi": model})  # fmt: skip
    assert {r["policy"] for r in table} >= {"scripted", "multi"}
    with pytest.raises(ValueError, match="takes no frame_stack"):
        SB3Policy(policy.model, policy.vecnormalize, frame_stack=2)
    for bad in ({"norm_obs": True, "norm_obs_keys": ["image", "vector"]},
                {"norm_obs": True, "norm_obs_keys": None}):  # fmt: skip
        with pytest.raises(ValueError, match="norm_obs on an image"):
            train("ppo", {**config, "normalize": bad}, tmp_path / "refused", seed=0,
                  progress_bar=False)  # fmt: skip
    assert not (tmp_path / "refused").exists()
    # a residual agent over the follower, which reads the vector part
    residual = {**config, "env_wrapper": [
        {"training.common.ResidualAction": {"base": "scripted", "scale": 0.5}}]}  # fmt: skip
    path = train("ppo", residual, tmp_path / "residual", seed=0, progress_bar=False)
    env = make_env(dict_env, 30)
    agent = load_policy(path, env=env)
    assert agent.base is not None and agent.scale == 0.5
    twin = load_policy(path, env=env).base  # a copy of its base, kept in step with it
    obs, _ = env.reset(seed=2, options={"target": "jog"})
    agent.reset(2)
    twin.reset(2)
    for _ in range(3):
        model_obs = {"image": obs["image"][None],
                     "vector": agent.vecnormalize.normalize_obs(
                         {"vector": obs["vector"][None]})["vector"]}  # fmt: skip
        a, _ = agent.model.predict(model_obs, deterministic=True)
        got = agent.act(obs)
        np.testing.assert_array_equal(got, combine(twin.act(obs["vector"]), a.reshape(-1), 0.5))
        obs, *_ = env.step(got)
    env.close()


def test_a_residual_agent_that_observes_its_base_acts_alike_in_training_and_at_inference(
    tmp_path: Path,
) -> None:
    """With observe_base the training wrapper shows the agent the env's observation
    followed by the follower's action, and the loaded policy rebuilds that observation:
    the wrapper driven by the model's own predictions and the loaded policy lay the same
    trajectory, bit for bit."""
    import gymnasium as gym
    from stable_baselines3 import PPO

    from policies.residual import make_base_policy
    from policies.sb3 import load_vecnormalize, vecnormalize_path
    from training.common import ResidualAction, make_env
    from training.train import train

    kwargs = {"base": "scripted", "scale": 1.0, "observe_base": True}
    config = {**tiny_config(), "n_timesteps": 64,
              "env_wrapper": [{"training.common.ResidualAction": kwargs}]}  # fmt: skip
    model_path = train("ppo", config, tmp_path / "resid", seed=0, progress_bar=False)

    wrapped = ResidualAction(make_env(SMALL, 30), **kwargs)
    inner = wrapped.env.observation_space.shape[0]
    assert wrapped.observation_space.shape == (inner + 2,)
    obs, _ = wrapped.reset(seed=3)
    fresh = make_env(SMALL, 30)
    follower = make_base_policy("scripted", fresh)
    raw0, _ = fresh.reset(seed=3)
    follower.reset(3)
    np.testing.assert_array_equal(obs[:inner], raw0)
    np.testing.assert_array_equal(obs[inner:], follower.act(raw0))  # the base's action
    fresh.close()
    model = PPO.load(str(model_path), device="cpu")
    vn = load_vecnormalize(vecnormalize_path(model_path))
    via_wrapper = [obs[:inner]]
    for _ in range(6):
        a, _ = model.predict(vn.normalize_obs(obs[None]), deterministic=True)
        obs, *_ = wrapped.step(a.reshape(-1))
        via_wrapper.append(obs[:inner])

    env = gym.make("CNTDeposit-v0", **SMALL)
    policy = load_policy(model_path, env=env)
    assert policy.observe_base
    raw, _ = env.reset(seed=3)
    policy.reset(3)
    via_policy = [raw]
    for _ in range(6):
        raw, *_ = env.step(policy.act(raw))
        via_policy.append(raw)
    env.close()
    np.testing.assert_array_equal(np.array(via_wrapper), np.array(via_policy))


def test_every_training_config_trains_on_the_surrogate_and_eval_yml_keeps_the_model() -> None:
    """Each YAML in training/configs names env keywords the env accepts; the training
    configs and the pretrained models' configs pin the fast surrogate
    (presets.SURROGATE: the printed drag law at delta_bar 1), and the evaluation config
    (training/configs/eval.yml, cnt-evaluate's default) keeps the env's default physics,
    the model (presets.MODEL on presets.MESH's delta_bar). Probes:
    ppo_residual_linear.yml trains on the linear law at delta_bar 1,
    ppo_residual_calibrated.yml (and ppo_residual_calibrated_detour.yml, its routes
    weighted toward the detour family) on the surrogate calibrated to the model's
    kinematics (its flow x 1.44, a control step of 99 physics steps instead of 150), and
    ppo_residual_linear033.yml (and its _detour twin, and its _finetune twin, which goes
    on training a calibrated agent) on the model's law on a coarser rod (delta_bar 0.33);
    ppo_residual_detour.yml is ppo_residual.yml's _detour twin,
    ppo_residual_calibrated_detour2.yml weights detour more mildly (2 in 9), and
    ppo_residual_calibrated_curriculum.yml starts at 3 in 10 and ends on every family
    once (training.callbacks.Curriculum), ppo_residual_calibrated_open_then_detour.yml the
    other way round; ppo_residual_shipped_detour_finetune.yml goes on training a trained
    agent on the calibrated surrogate, detour 3 in 10, and is the last stage of the
    shipped residual agent, whose policies/pretrained/ppo_residual.yml is that stage's;
    sac_residual.yml (and its _sde twin) trains residual SAC on the calibrated surrogate,
    detour 2 in 9; ppo_residual_start_model.yml goes on training the shipped agent on the
    model itself, on the first control steps of its episodes, and
    ppo_residual_model_detour_finetune.yml on the model's detours;
    ppo_residual_detour_only_finetune.yml is the shipped detour stage drawing detours
    only (a keep-out split's specialist); ppo_lstm_residual_recipe.yml and
    ppo_lstm_residual_detour_finetune.yml are the shipped recipe's two stages with a
    recurrent policy, and their *_gainrand_* twins (and the MLP pair
    ppo_residual_gainrand_*) draw the flow gain per episode."""
    from cnt_env.presets import MESH, MODEL, SURROGATE
    from cnt_env.task.routes import FAMILIES
    from training.common import (
        curriculum_settings,
        env_settings,
        eval_env_settings,
        load_config,
        make_env,
    )

    root = Path(__file__).resolve().parents[1]
    configs = sorted((root / "training" / "configs").glob("*.yml"))
    configs += sorted((root / "policies" / "pretrained").glob("*.yml"))
    shipped_residual = root / "policies" / "pretrained" / "ppo_residual.yml"
    assert any(p.name == "eval.yml" for p in configs)
    surrogate = (SURROGATE["drag_law"], SURROGATE["delta_bar"])
    model = (MODEL["drag_law"], MESH["serpentine"]["delta_bar"])
    assert surrogate != model
    expected = {"eval.yml": model, "ppo_residual_linear.yml": ("linear", 1.0),
                "ppo_residual_linear033.yml": (MODEL["drag_law"], 0.33),
                "ppo_residual_linear033_finetune.yml": (MODEL["drag_law"], 0.33),
                "ppo_residual_start_model.yml": model,
                "ppo_residual_model_detour_finetune.yml": model}  # fmt: skip
    # (detours, families) of each weighted twin; a curriculum twin's first draw, and its
    # last stage's (every family once: (1, len(FAMILIES)))
    once = (1, len(FAMILIES))
    detour_share = {"_detour.yml": (3, 10), "_detour2.yml": (2, 9), "_curriculum.yml": (3, 10),
                    "_open_then_detour.yml": once}  # fmt: skip
    last_share = {"_curriculum.yml": once, "_open_then_detour.yml": (3, 10)}
    calibrated_share = {
        "sac_residual.yml": (2, 9),
        "sac_residual_sde.yml": (2, 9),
        "ppo_residual_detour_only_finetune.yml": (1, 1),
    }  # other names
    for path in configs:
        # the longest suffix that matches (_open_then_detour.yml also ends in _detour.yml)
        suffix = max((k for k in detour_share if path.name.endswith(k)), key=len, default=None)
        twin_of = path.name.removesuffix(suffix or ".yml") + ".yml"  # a weighted twin: its physics
        shipped_last_stage = path.name in SECOND_STAGES or path == shipped_residual
        config = load_config(path)
        env_kwargs, steps = env_settings(config)
        env = make_env(env_kwargs, steps)  # constructs the simulator config; no reset
        try:
            base = env.unwrapped
            physics = (base.config.drag_law, base.params.delta_bar)
            assert physics == expected.get(twin_of, surrogate), path.name
            calibrated = twin_of == "ppo_residual_calibrated.yml" or path.name in calibrated_share
            if "_gainrand_" in path.name:  # the gain drawn per episode, evaluated at 1.44
                assert base.flow_gain_range == (1.0, 2.0), path.name
                ev_env = make_env(*eval_env_settings(config))
                ev = ev_env.unwrapped
                assert (ev.flow_gain_range, ev.flow_gain, ev.n_substeps) == (None, 1.44, 99)
                ev_env.close()
            elif calibrated or shipped_last_stage:
                assert (base.flow_gain, base.n_substeps) == (1.44, 99)
            else:
                assert base.flow_gain == 1.0, path.name
            share = (base.families.count("detour"), len(base.families))
            ranged = path.name.startswith("ppo_residual_difficulty_range")
            assert base.difficulty == ((0.25, 1.0) if ranged else 0.5), path.name
            if suffix is not None:  # the detour family repeated in the drawn families
                assert share == detour_share[suffix], path.name
            elif shipped_last_stage or path.name in GAINRAND_SECOND_STAGES:
                assert share == (3, 10), path.name
            elif path.name in calibrated_share:
                assert share == calibrated_share[path.name], path.name
            stages = curriculum_settings(config)  # a curriculum is well formed
            assert bool(stages) == (suffix in last_share), path.name
            if stages:  # ... and ends on its last draw, every family drawn
                last = stages[-1][1]["families"]
                assert set(last) == set(FAMILIES), path.name
                assert (last.count("detour"), len(last)) == last_share[suffix], path.name
        finally:
            env.close()


def test_curriculum_switches_the_route_draw_at_its_stages(tmp_path: Path) -> None:
    """training.callbacks.Curriculum: the training envs draw from env_kwargs' families
    until the stage's share of the budget, then from the stage's (each env's next reset;
    CNTDeposit-v0.set_route_draw through VecEnv.env_method), and tensorboard logs
    curriculum/stage."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import DummyVecEnv

    from training.callbacks import make_curriculum
    from training.common import curriculum_settings, make_env

    config = {**tiny_config(), "env_kwargs": {**SMALL, "families": ["straight", "detour"]},
              "callback": [{"training.callbacks.Curriculum": {"stages": [
                  {"at": 0.5, "families": ["arc"], "difficulty": 0.2}]}}]}  # fmt: skip
    stages = curriculum_settings(config)
    assert stages == [(0.5, {"families": ["arc"], "difficulty": 0.2})]
    venv = DummyVecEnv([lambda: make_env(config["env_kwargs"], 30)])
    drawn: list[tuple[str, ...]] = []

    class Spy(BaseCallback):
        def _on_step(self) -> bool:
            drawn.append(tuple(self.training_env.get_attr("families")[0]))
            return True

    model = PPO("MlpPolicy", venv, n_steps=32, batch_size=32, n_epochs=1, seed=0,
                tensorboard_log=str(tmp_path), policy_kwargs={"net_arch": [8]})  # fmt: skip
    model.learn(128, callback=[make_curriculum([(64, stages[0][1])]), Spy()])
    assert drawn[0] == ("straight", "detour") and drawn[-1] == ("arc",)
    assert drawn.index(("arc",)) == 63  # the callback runs first, at num_timesteps 64
    assert venv.get_attr("difficulty") == [0.2]
    events = b"".join(p.read_bytes() for p in tmp_path.rglob("events.out.tfevents*"))
    assert b"curriculum/stage" in events
    venv.close()


@pytest.mark.parametrize(
    ("stages", "match"),
    [
        ([{"at": 0.5}], "at, families and/or difficulty"),
        ([{"families": ["arc"]}], "at, families and/or difficulty"),
        ([{"at": 0.5, "families": ["arc"], "width": 3}], "at, families and/or difficulty"),
        ([{"at": 1.0, "families": ["arc"]}], "0 < at < 1"),
        ([{"at": 0.6, "difficulty": 0.3}, {"at": 0.4, "difficulty": 0.5}], "increasing"),
        ([{"at": 0.5, "families": ["spiral"]}], "unknown training family 'spiral'"),
        ([{"at": 0.5, "difficulty": 1.5}], r"difficulty must be in \[0, 1\]"),
        ([], "non-empty list"),
    ],
)
def test_a_bad_curriculum_is_refused_before_training(stages: list, match: str) -> None:
    from training.common import curriculum_settings

    config = {"callback": [{"training.callbacks.Curriculum": {"stages": stages}}]}
    with pytest.raises(ValueError, match=match):
        curriculum_settings(config)


def test_an_unknown_callback_is_refused_and_every_shipped_config_passes() -> None:
    """A misspelt callback would train silently without it: check_callbacks refuses it
    (cnt-train calls it before building any env); the shipped configs pass."""
    from training.common import CONFIG_DIR, check_callbacks, load_config

    for path in sorted(CONFIG_DIR.glob("*.yml")):
        check_callbacks(load_config(path))
    for bad in ("training.callbacks.Curiculum", [{"training.callbacks.HeldOutEvl": {}}]):
        with pytest.raises(ValueError, match="unknown callback"):
            check_callbacks({"callback": bad})
    check_callbacks({"callback": "training.callbacks.Checkpoint"})  # a single entry


def test_a_saved_agent_goes_on_training_from_its_weights_and_statistics(tmp_path: Path) -> None:
    """``trained_agent`` (cnt-train --trained-agent) starts from the saved weights and
    VecNormalize statistics: at a learning rate of 0 the weights come out unchanged (a new
    model's would differ) and the statistics count the saved observations plus the new
    ones. An agent that would act on something else is refused before any env is built."""
    import torch
    import yaml
    from stable_baselines3 import PPO

    from policies.sb3 import file_sha256, load_vecnormalize, write_manifest
    from training.train import check_trained_agent, train

    config = {**tiny_config(), "n_timesteps": 64, "env_wrapper": [
        {"training.common.ResidualAction": {"base": "scripted", "scale": 0.3}}]}  # fmt: skip
    first = train("ppo", config, tmp_path / "first", seed=0, progress_bar=False)
    again = train("ppo", {**config, "learning_rate": 0.0}, tmp_path / "again", seed=5,
                  progress_bar=False, trained_agent=first)  # fmt: skip
    fresh = train("ppo", {**config, "learning_rate": 0.0}, tmp_path / "fresh", seed=5,
                  progress_bar=False)  # fmt: skip

    def weights(path: Path) -> list[torch.Tensor]:
        return list(PPO.load(path, device="cpu").policy.state_dict().values())

    w0, w1, w2 = weights(first), weights(again), weights(fresh)
    assert all(torch.equal(a, b) for a, b in zip(w0, w1, strict=True))
    assert not all(torch.equal(a, b) for a, b in zip(w0, w2, strict=True))
    stem = "ppo_vecnormalize"
    n0, n1, n2 = (load_vecnormalize(p.with_name(stem)).obs_rms.count for p in (first, again, fresh))
    assert n1 == pytest.approx(n0 + n2 - 1e-4), (n0, n1, n2)  # 1e-4: the initial count
    record = yaml.safe_load((again.parent / "config.yml").read_text())["run"]["trained_agent"]
    assert record["path"] == str(first) and record["run"]["timesteps_done"] == 64
    assert record["sha256"] == file_sha256(first)

    other_base = {**config, "env_wrapper": [{"training.common.ResidualAction": {
        "base": "scripted", "scale": 0.5}}]}  # fmt: skip
    plain = {k: v for k, v in config.items() if k != "env_wrapper"}
    for cfg, match in ((other_base, "residual settings"), (plain, "residual settings"),
                       ({**config, "normalize": False}, "VecNormalize"),
                       ({**config, "frame_stack": 2}, "frame stack")):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            train("ppo", cfg, tmp_path / "bad", seed=0, progress_bar=False, trained_agent=first)
        assert not (tmp_path / "bad" / "monitor").exists(), "refused after building envs"
    # other options of the same base follower: refused, unless asked for, and recorded
    other_options = {**config, "env_wrapper": [{"training.common.ResidualAction": {
        "base": "scripted", "scale": 0.3, "base_kwargs": {"lookahead": 12.0}}}]}  # fmt: skip
    with pytest.raises(ValueError, match="--new-base-options"):
        check_trained_agent(first, "ppo", other_options)
    with pytest.raises(ValueError, match="residual settings"):  # another scale: never
        check_trained_agent(first, "ppo", other_base, new_base_options=True)
    record = check_trained_agent(first, "ppo", other_options, new_base_options=True)
    assert record["base_kwargs_was"]["lookahead"] == 20.0  # the follower's default
    assert "base_kwargs_was" not in check_trained_agent(first, "ppo", config, True)
    from training.train import main as train_main

    with pytest.raises(SystemExit) as stop:  # the flag alone would be silently ignored
        train_main(["--algo", "ppo", "--new-base-options", "--out", str(tmp_path / "cli")])
    assert stop.value.code == 2 and not (tmp_path / "cli").exists()
    with pytest.raises(ValueError, match="is a ppo agent"):
        train("sac", config, tmp_path / "bad1", seed=0, progress_bar=False, trained_agent=first)
    with pytest.raises(ValueError, match="policy"):  # SB3's own check of policy_kwargs
        train("ppo", {**config, "policy_kwargs": {"net_arch": [8]}}, tmp_path / "bad2",
              seed=0, progress_bar=False, trained_agent=first)  # fmt: skip
    first.with_suffix(".yml").unlink()
    write_manifest(first.parent, [f.name for f in first.parent.glob("ppo*") if f.is_file()])
    with pytest.raises(ValueError, match="resolved config"):
        train("ppo", config, tmp_path / "bad3", seed=0, progress_bar=False, trained_agent=first)


def test_the_finetune_config_acts_on_the_shipped_agents_own_base() -> None:
    """ppo_residual_shipped_detour_finetune.yml (the shipped agent's second stage) goes on
    training the shipped agent once its base has the start flow and the recent plan band
    the agent was given after training: cnt-train's check (same algorithm, base with the
    same pinned options, frame stack, normalisation) accepts the pair then and not before,
    and a config on today's follower is refused."""
    from training.common import CONFIG_DIR, load_config
    from training.train import check_trained_agent

    shipped = PRETRAINED_DIR / "ppo_residual.zip"
    config = load_config(CONFIG_DIR / SHIPPED_FINETUNE)
    # the shipped agent's base gained the follower's start flow and its recent plan band
    # after training (its yml): refused with either missing
    base = config["env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]
    with pytest.raises(ValueError, match="residual settings"):
        check_trained_agent(shipped, "ppo", config)
    base["start_swing"] = True
    with pytest.raises(ValueError, match="residual settings"):
        check_trained_agent(shipped, "ppo", config)
    base["band_memory"] = 8
    record = check_trained_agent(shipped, "ppo", config)
    assert record["path"] == str(shipped) and len(record["sha256"]) == 64
    # keepout_headings (which routes go to the follower) is not what the network acts on:
    # the shipped agent's [-z] goes on training under none or another
    config["env_wrapper"][0]["training.common.ResidualAction"]["keepout_headings"] = ["+z"]
    assert check_trained_agent(shipped, "ppo", config)["path"] == str(shipped)
    with pytest.raises(ValueError, match="residual settings"):
        check_trained_agent(shipped, "ppo", load_config(CONFIG_DIR / "ppo_residual_calibrated.yml"))


@pytest.mark.parametrize(
    ("module", "argv", "flag"),
    [
        ("training.evaluate", ["--policies=--"], "--policies"),
        ("training.evaluate", ["--reuse", "--seeds=--"], "--seeds"),  # [] of --reuse is fine
        ("training.train", ["--algo=--"], "--algo"),
        ("training.demo", ["--out=--"], "--out"),
    ],
)
def test_an_option_given_double_dash_is_a_usage_error(
    module: str, argv: list[str], flag: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """argparse stores [] for ``--opt=--``; the training CLIs stop with a usage error
    (exit 2) naming the option, before any work, instead of a traceback further on."""
    import importlib

    with pytest.raises(SystemExit) as exc:
        importlib.import_module(module).main(argv)
    assert exc.value.code == 2
    assert f"{flag} got '--' as its value" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("module", "argv", "message"),
    [
        ("training.train", ["--algo", "ppo", "--n-timesteps", "0"], "--n-timesteps: must be"),
        ("training.train", ["--algo", "ppo", "--n-envs", "-1"], "--n-envs: must be"),
        ("training.train", ["--algo", "sac", "--max-episode-steps", "0"], "--max-episode-steps"),
        ("training.train", ["--algo", "ppo", "--max-wall-seconds", "nan"], "finite number > 0"),
        ("training.train", ["--algo", "ppo", "--seed", "-3"], "a seed must be ≥ 0"),
        ("training.train", ["--algo", "ppo", "--config", "{tmp}/missing.yml"], "cannot read"),
        ("training.train", ["--algo", "ppo", "--config", "{tmp}/bad.yml"], "not valid YAML"),
        ("training.train", ["--algo", "ppo", "--config", "{tmp}/list.yml"], "has no entry"),
        ("training.train", ["--algo", "ppo", "--config", "{tmp}/zero.yml"], "n_timesteps must"),
        ("training.train", ["--algo", "ppo", "--trained-agent", "{tmp}/bad.zip"], "not valid YAML"),
        ("training.train", ["--algo", "ppo", "--trained-agent", "{tmp}/no.zip"], "no model at"),
        ("training.evaluate", ["--seeds", "0,-1"], "--seeds: a seed must be ≥ 0"),
        ("training.evaluate", ["--seeds", ","], "--seeds: give at least one seed"),
        ("training.evaluate", ["--targets", "u_turn,nosuch"], "['nosuch']: not held-out"),
        ("training.evaluate", ["--policies", "random,randum"], "'randum' is neither a baseline"),
        ("training.demo", ["--targets", "nosuch"], "--targets: ['nosuch']: not held-out"),
        ("training.demo", ["--seeds", "-1"], "--seeds: a seed must be ≥ 0"),
        ("training.demo", ["--budget-minutes", "-1"], "finite number > 0"),
        ("training.demo", ["--jobs", "0"], "--jobs: must be a positive integer"),
        ("training.evaluate", ["--jobs", "0"], "--jobs: must be a positive integer"),
        ("training.evaluate", ["--config", "{tmp}/bad.yml"], "--config: the config"),
        ("training.evaluate", ["--route-file", "{tmp}/bad.yml"], "--route-file: "),
        ("training.evaluate", ["--route-file", "{tmp}/missing.json"], "cannot be read"),
        (
            "training.evaluate",
            ["--route-file", "{tmp}/routes.json", "--targets", "nosuch"],
            "['nosuch']: not held-out",
        ),
    ],
)
def test_bad_training_input_is_a_usage_error_that_makes_nothing(
    module: str, argv: list[str], message: str, tmp_path: Path,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """A bad number, a missing or corrupt config, or a corrupt --trained-agent stops
    cnt-train / cnt-evaluate / cnt-demo with a usage error (exit 2) that says what is wrong, before
    any run directory or results directory is made (found by hand-fuzzing both CLIs:
    before, tracebacks from a worker process, a 0-step 'run' for --n-timesteps -5)."""
    import importlib

    (tmp_path / "bad.yml").write_text("garbage: [\n")
    (tmp_path / "bad.zip").write_bytes(b"not a zip")  # its .yml is bad.yml
    (tmp_path / "list.yml").write_text("- a\n")
    (tmp_path / "zero.yml").write_text("CNTDeposit-v0: {n_timesteps: 0}\n")
    (tmp_path / "routes.json").write_text('{"a": {"waypoints": [[0, 0], [30, 0]]}}')
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    argv = [a.replace("{tmp}", str(tmp_path)) for a in argv]
    with pytest.raises(SystemExit) as exc:
        importlib.import_module(module).main([*argv, "--out", str(work / "out")])
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
    assert list(work.iterdir()) == []  # no run or results directory, no runs/ default


def test_two_stages_share_one_budget_and_the_second_goes_on_from_the_first(
    tmp_path: Path,
) -> None:
    """training.two_stage: stage 2 goes on training stage 1's final model over its own
    base options (recorded as base_kwargs_was), with n_timesteps = the time left x the
    rate; nothing left, or a stage 2 that cannot take stage 1's agent, is refused before
    anything trains."""
    from training.two_stage import main as two_stage_main
    from training.two_stage import run_two_stages, stage2_budget

    def residual(**base_kwargs: float) -> dict:
        return {**tiny_config(), "n_timesteps": 64, "env_wrapper": [
            {"training.common.ResidualAction": {"base": "scripted", "scale": 0.3,
                                                "base_kwargs": base_kwargs}}]}  # fmt: skip

    stage1, stage2 = residual(), residual(lookahead=12.0)
    model = run_two_stages("ppo", stage1, stage2, tmp_path / "run", seed=0, stage2_seed=0,
                           stage1_s=600.0, total_s=900.0, steps_per_second=0.1,
                           startup_s=45.0)  # fmt: skip
    first = tmp_path / "run" / "stage1" / "ppo.zip"
    assert model == tmp_path / "run" / "stage2" / "ppo.zip" and first.is_file()
    resolved = yaml.safe_load((model.parent / "config.yml").read_text())
    record = resolved["run"]["trained_agent"]
    assert record["path"] == str(first) and record["base_kwargs_was"]["lookahead"] == 20.0
    base = resolved["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"]
    assert base["base_kwargs"]["lookahead"] == 12.0
    timing = json.loads((tmp_path / "run" / "timing.json").read_text())
    assert timing["stage2_n_timesteps"] == int(timing["stage2_budget_s"] * 0.1)
    assert resolved["CNTDeposit-v0"]["n_timesteps"] == timing["stage2_n_timesteps"]
    assert resolved["run"]["max_wall_seconds"] == pytest.approx(timing["stage2_budget_s"], abs=0.1)
    assert timing["stage2_budget_s"] == pytest.approx(900.0 - 45.0 - timing["stage1_s"], abs=0.2)

    # a stage 2 tried again over the same stage 1: its spent time counts, nothing retrains
    again = run_two_stages("ppo", {}, stage2, tmp_path / "again", seed=0, stage2_seed=1,
                           stage1_s=0.0, total_s=900.0, steps_per_second=0.1,
                           stage1_model=first, stage1_spent_s=300.0)  # fmt: skip
    timing = json.loads((tmp_path / "again" / "timing.json").read_text())
    assert not (tmp_path / "again" / "stage1").exists() and again.is_file()
    assert timing["stage2_budget_s"] == pytest.approx(900.0 - 45.0 - 300.0, abs=0.2)
    assert timing["stage1_model"] == str(first)
    resolved = yaml.safe_load((again.parent / "config.yml").read_text())
    assert resolved["run"]["trained_agent"]["path"] == str(first)

    assert stage2_budget(100.0, 20.0, 10.0, 2.0) == (70.0, 140)
    with pytest.raises(ValueError, match="no time is left"):
        stage2_budget(100.0, 90.0, 45.0, 50.0)
    cfg1, cfg2 = tmp_path / "s1.yml", tmp_path / "s2.yml"
    cfg1.write_text(yaml.safe_dump({"CNTDeposit-v0": stage1}))
    other_scale = residual()
    other_scale["env_wrapper"][0]["training.common.ResidualAction"]["scale"] = 0.5
    cfg2.write_text(yaml.safe_dump({"CNTDeposit-v0": other_scale}))
    for argv in (["--stage1-seconds", "900", "--total-seconds", "900"], []):
        with pytest.raises(SystemExit) as stop:
            two_stage_main(["--stage1", str(cfg1), "--stage2", str(cfg2), *argv,
                            "--out", str(tmp_path / "cli")])  # fmt: skip
        assert stop.value.code == 2 and not (tmp_path / "cli").exists()
    cfg3 = tmp_path / "s3.yml"  # a stage 2 that stage 1's agent fits
    cfg3.write_text(yaml.safe_dump({"CNTDeposit-v0": stage2}))
    for argv in (
        ["--stage1", str(cfg1), "--stage1-model", str(first), "--stage1-spent", "300"],
        ["--stage1-model", str(first)],  # its spent time is needed
        ["--stage1-model", str(tmp_path / "none.zip"), "--stage1-spent", "300"],
        ["--stage1-model", str(first), "--stage1-spent", "900"],  # nothing left
        ["--stage1-model", str(first), "--stage1-spent", "880"],  # less than the start-up
        ["--stage1-model", str(first), "--stage1-spent", "300", "--stage2", str(cfg2)],
    ):  # the last: another residual scale than the trained model's
        argv = argv if "--stage2" in argv else [*argv, "--stage2", str(cfg3)]
        with pytest.raises(SystemExit) as stop:  # (a regression trains ~1 step, not hours)
            two_stage_main([*argv, "--total-seconds", "900", "--steps-per-second", "0.01",
                            "--out", str(tmp_path / "cli")])  # fmt: skip
        assert stop.value.code == 2 and not (tmp_path / "cli").exists()

    # over a given first stage the run is named by stage 2's seed (--seed trains nothing)
    for _ in range(2):
        assert two_stage_main(["--stage1-model", str(first), "--stage1-spent", "300",
                               "--stage2", str(cfg3), "--seed", "5", "--stage2-seed", "3",
                               "--total-seconds", "900", "--steps-per-second", "0.1",
                               "--out", str(tmp_path / "cli")]) == 0  # fmt: skip
    assert sorted(p.name for p in (tmp_path / "cli").iterdir()) == ["stage2_s3", "stage2_s3_2"]


ROUTE_RUNS = Path(__file__).resolve().parents[1] / "training" / "results" / "route_runs"
SHIPPED_NOTE = "the shipped agent's base (policies/pretrained/ppo_residual.yml)"


@pytest.mark.parametrize(
    ("run", "name", "mirror_average"),
    [("mirror_hour", "mh_final", False), ("mirror_stage1", "ms_final_avg", True)],
)
def test_candidate_config_rebuilds_the_committed_candidates_to_the_byte(
    run: str, name: str, mirror_average: bool
) -> None:
    """training.candidate: a run's config over the shipped agent's base and gate is the
    model config that run's drive.sh wrote inline (while the shipped config is the one
    they were made with)."""
    from training.candidate import candidate_config

    d = ROUTE_RUNS / run
    text = candidate_config(
        yaml.safe_load((d / "config.yml").read_text()),
        yaml.safe_load((PRETRAINED_DIR / "ppo_residual.yml").read_text()),
        SHIPPED_NOTE,
        mirror_average,
    )
    assert text == (d / "model" / f"{name}.yml").read_text()


def test_make_candidate_copies_the_model_sets_the_options_and_rewrites_the_manifest(
    tmp_path: Path,
) -> None:
    from policies.sb3 import check_manifest
    from training.candidate import main as candidate_main

    run = tmp_path / "run"
    run.mkdir()
    cfg = yaml.safe_load((ROUTE_RUNS / "mirror_stage1" / "config.yml").read_text())
    (run / "ppo.yml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    for suffix, data in ((".zip", b"net"), ("_vecnormalize.npz", b"npz"),
                         ("_vecnormalize.json", b"{}")):  # fmt: skip
        (run / f"ppo{suffix}").write_bytes(data)
    out = tmp_path / "models"
    argv = [str(run / "ppo.zip"), "--like", str(PRETRAINED_DIR / "ppo_residual.yml"),
            "--out", str(out), "--keepout-headings=-z,+z"]  # fmt: skip
    assert candidate_main([*argv, "--name", "a"]) == 0
    assert candidate_main([*argv, "--name", "b", "--mirror-average"]) == 0
    assert (out / "a.zip").read_bytes() == b"net"
    assert (out / "b_vecnormalize.npz").read_bytes() == b"npz"
    wrap = {}
    for n in ("a", "b"):
        c = yaml.safe_load((out / f"{n}.yml").read_text())
        wrap[n] = c["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"]
        assert wrap[n]["keepout_headings"] == ["-z", "+z"]
        assert c["run"]["base_set_after_training"].endswith("gate [-z, +z]")
        assert check_manifest(out / f"{n}.zip")  # both candidates listed
    shipped = yaml.safe_load((PRETRAINED_DIR / "ppo_residual.yml").read_text())
    like = shipped["CNTDeposit-v0"]["env_wrapper"][0]["training.common.ResidualAction"]
    assert wrap["a"]["base_kwargs"] == like["base_kwargs"] != cfg["CNTDeposit-v0"][
        "env_wrapper"][0]["training.common.ResidualAction"]["base_kwargs"]  # fmt: skip
    assert "mirror_average" not in wrap["a"] and wrap["b"]["mirror_average"] is True


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--name", "x"], "lacks"),  # no statistics or .yml beside the zip
        (["--name", "a/b"], "bare file stem"),
        (["--name", "x", "--keepout-headings", "up"], "headings are"),
    ],
)
def test_candidate_bad_input_is_a_usage_error(tmp_path: Path, capsys, argv, message) -> None:
    from training.candidate import main as candidate_main

    (tmp_path / "ppo.zip").write_bytes(b"net")
    with pytest.raises(SystemExit) as exc:
        like = str(PRETRAINED_DIR / "ppo_residual.yml")
        candidate_main([str(tmp_path / "ppo.zip"), "--like", like, "--out", str(tmp_path / "m"),
                        *argv])  # fmt: skip
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
