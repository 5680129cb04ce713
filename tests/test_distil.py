"""The planning oracle (training/oracle.py) and its distillation (training/distil.py):
the candidates in closed form, the rollout algorithm's exactness on the deterministic
env (its predicted score is the one it realises, never below the follower's), the
imitation targets, and a fitted agent that loads as a residual policy."""

from __future__ import annotations

import copy
import itertools
import json
import math
from pathlib import Path

import gymnasium
import numpy as np
import pytest

from cnt_env.task.spaces import flow_from_action
from policies import RouteFollower, load_policy
from training import distil
from training.oracle import RolloutOracle, candidates

ROUTE = {"waypoints": [[0, 0], [60, 0]], "width": 15.0}


# warm states in a temporary cache, whatever a test forgets to pass (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("temp_warm_cache")


def test_candidates_turn_and_slow_the_followers_flow() -> None:
    a = np.array([0.3, -0.5], dtype=np.float32)
    v0, p0 = flow_from_action(a, 0.13)
    cands = candidates(a, 0.13, turns=(-0.4, 0.4), speeds=(0.5,))
    assert len(cands) == 4 and np.array_equal(cands[0], a)
    for c, dphi in zip(cands[1:3], (-0.4, 0.4), strict=True):
        v, p = flow_from_action(c, 0.13)
        assert v == pytest.approx(v0, rel=1e-5)
        assert math.remainder(p - p0 - dphi, 2 * math.pi) == pytest.approx(0.0, abs=1e-5)
    v, p = flow_from_action(cands[3], 0.13)
    assert v == pytest.approx(0.5 * v0, rel=1e-5)
    assert math.remainder(p - p0, 2 * math.pi) == pytest.approx(0.0, abs=1e-5)


def _short_env() -> gymnasium.Env:
    return gymnasium.make("CNTDeposit-v0", score="corridor", max_episode_steps=5)


def _follower_score(env: gymnasium.Env, follower: RouteFollower) -> float:
    """The final score of the follower's own episode on ROUTE at reset seed 3."""
    obs, info = env.reset(seed=3, options={"target": ROUTE})
    follower.reset(3)
    term = trunc = False
    while not (term or trunc):
        obs, _, term, trunc, info = env.step(follower.act(obs))
    return float(info["score"])


def test_rollout_oracle_realises_its_prediction_and_never_loses_to_the_follower() -> None:
    env = _short_env()
    try:
        follower = RouteFollower.from_env(env)
        follower_score = _follower_score(env, follower)
        obs, info = env.reset(seed=3, options={"target": ROUTE})
        follower.reset(3)
        oracle = RolloutOracle(env, follower, turns=(0.4,), speeds=())
        predicted, first = [], None
        term = trunc = False
        while not (term or trunc):
            cands, scores, k = oracle.choose(obs, info)
            first = scores if first is None else first
            predicted.append(scores[k])
            obs, _, term, trunc, info = env.step(cands[k])
        # the first base rollout is the follower's own episode, bit for bit
        assert first[0] == follower_score
        assert oracle.rollouts == 1 + len(predicted) and len(oracle.history) == len(predicted)
        # the deterministic env realises every prediction exactly; scores never fall
        assert all(b >= a for a, b in itertools.pairwise(predicted))
        assert float(info["score"]) == predicted[-1]
        assert float(info["score"]) >= follower_score
    finally:
        env.close()


def _play_oracle(
    env: gymnasium.Env, horizon: int | None
) -> tuple[list[int], list[float], list[float]]:
    """One oracle episode: its choices, the score it predicted for each choice and the
    score Φ realised after each step."""
    follower = RouteFollower.from_env(env)
    obs, info = env.reset(seed=3, options={"target": ROUTE})
    follower.reset(3)
    oracle = RolloutOracle(env, follower, turns=(0.4,), speeds=(0.5,), horizon=horizon)
    predicted, realised = [], []
    term = trunc = False
    while not (term or trunc):
        cands, scores, k = oracle.choose(obs, info)
        predicted.append(scores[k])
        obs, _, term, trunc, info = env.step(cands[k])
        realised.append(float(info["score"]))
    return oracle.history, predicted, realised


def test_a_horizon_past_the_episode_end_is_the_rollout_algorithm() -> None:
    """Truncated rollouts that reach the end are the full ones: the same choices and the
    same predicted and realised scores, bit for bit."""
    env = gymnasium.make("CNTDeposit-v0", score="corridor", max_episode_steps=4,
                         drag_law="printed", delta_bar=1.0)  # fmt: skip
    try:
        full = _play_oracle(env, None)
        assert _play_oracle(env, 4) == full
    finally:
        env.close()


def test_horizon_zero_predicts_the_score_after_the_step_exactly() -> None:
    """With horizon 0 a candidate's score is Φ after its one step: on the deterministic env
    the chosen candidate's prediction is what the step realises, and it is the best of
    the candidates tried."""
    env = gymnasium.make("CNTDeposit-v0", score="corridor", max_episode_steps=4,
                         drag_law="printed", delta_bar=1.0)  # fmt: skip
    try:
        history, predicted, realised = _play_oracle(env, 0)
        assert predicted == realised and len(history) == 4
    finally:
        env.close()


def test_a_confirmed_screen_never_loses_to_the_follower_and_predicts_exactly() -> None:
    """``confirm``: a horizon-0 screen departs from the follower freely, and a departure
    is played only where its full rollout wins, so the final score is never below the
    follower's, each played departure's full rollout is what the episode realises, and
    the scores not rolled out to the end are NaN."""
    env = gymnasium.make("CNTDeposit-v0", score="corridor", max_episode_steps=5,
                         drag_law="printed", delta_bar=1.0)  # fmt: skip
    try:
        follower = RouteFollower.from_env(env)
        follower_score = _follower_score(env, follower)
        obs, info = env.reset(seed=3, options={"target": ROUTE})
        follower.reset(3)
        oracle = RolloutOracle(env, follower, turns=(-0.4, 0.4), speeds=(0.5,), horizon=0,
                               confirm=True)  # fmt: skip
        screen = RolloutOracle(copy.deepcopy(env), copy.deepcopy(follower),
                               turns=(-0.4, 0.4), speeds=(0.5,), horizon=0)  # fmt: skip
        predicted, screened, bases = [], [], []
        term = trunc = False
        while not (term or trunc):
            screen.env, screen.follower = copy.deepcopy((env, follower))
            screened.append(screen.choose(obs, info)[2])
            cands, scores, k = oracle.choose(obs, info)
            assert not math.isnan(scores[0]) and not math.isnan(scores[k])
            assert k in (0, screened[-1])
            assert all(math.isnan(s) for i, s in enumerate(scores) if i not in (0, screened[-1]))
            predicted.append(scores[k])
            bases.append(scores[0])
            obs, _, term, trunc, info = env.step(cands[k])
        assert bases[0] == follower_score  # the first base rollout is the follower's episode
        assert all(b >= a for a, b in itertools.pairwise(predicted))
        assert float(info["score"]) == predicted[-1] >= follower_score
        assert any(k > 0 for k in screened)  # the screen did depart: the check is not idle
    finally:
        env.close()


def test_confirm_needs_a_horizon(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match="confirm needs a horizon"):
        RolloutOracle(env=None, follower=None, confirm=True)  # type: ignore[arg-type]
    with pytest.raises(SystemExit) as exc:
        distil.main(["--confirm", "--out", "unused"])
    assert exc.value.code == 2 and "--confirm needs --horizon" in capsys.readouterr().err


@pytest.mark.parametrize("horizon", [-1, 1.5, True, "2"])
def test_a_bad_horizon_is_refused(horizon: object) -> None:
    with pytest.raises(ValueError, match="horizon"):
        RolloutOracle(env=None, follower=None, horizon=horizon)  # type: ignore[arg-type]


def _episode(obs: np.ndarray, follower: np.ndarray, cands: np.ndarray, scores: np.ndarray,
             chosen: np.ndarray, index: int) -> dict:  # fmt: skip
    summary = {"index": index, "difficulty": 0.2, "wall_s": 1.0}
    return {"obs": obs, "follower": follower, "candidates": cands, "scores": scores,
            "chosen": chosen, "summary": summary}  # fmt: skip


def test_targets_are_the_scaled_correction_where_the_oracle_gains_enough() -> None:
    f = np.array([[0.1, 0.2], [0.5, 0.5], [-0.9, 0.0]], dtype=np.float32)
    step = np.array([[0.0, 0.0], [0.3, 0.0], [0.0, -0.9]], dtype=np.float32)
    cands = f[:, None, :] + step[None]
    scores = np.array([[0.5, 0.6, 0.4], [0.5, 0.5005, 0.4], [0.5, 0.4, 0.9]])
    chosen = np.array([1, 1, 2])
    ep = _episode(np.zeros((3, 4)), f, cands, scores, chosen, 0)
    r = distil.targets(ep, scale=0.6, margin=0.001)
    assert r[0] == pytest.approx([0.5, 0.0])  # 0.3 / 0.6
    assert np.array_equal(r[1], [0.0, 0.0])  # gain 5e-4 <= margin: the follower's action
    assert r[2] == pytest.approx([0.0, -1.0])  # -0.9 / 0.6 clipped
    assert np.array_equal(distil.targets(ep, 0.6, 0.0)[1], [0.5, 0.0])


def test_fitted_agent_loads_as_a_residual_policy_and_acts_its_targets(tmp_path: Path) -> None:
    env = _short_env()
    try:
        obs0, _ = env.reset(seed=0, options={"target": ROUTE})
        rng = np.random.default_rng(0)
        labels = tmp_path / "labels"
        labels.mkdir()
        fixed = []
        for i in range(2):
            obs = (obs0 + rng.normal(0.0, 1.0, (3, obs0.size))).astype(np.float32)
            f = rng.uniform(-0.3, 0.3, (3, 2)).astype(np.float32)
            cands = np.stack([np.stack([a, a + rng.uniform(-0.4, 0.4, 2)]) for a in f])
            ep = _episode(obs, f, cands.astype(np.float32), np.array([[0.5, 0.7]] * 3),
                          np.array([1, 1, 1]), i)  # fmt: skip
            ep["summary"] = np.array(json.dumps(ep["summary"]))
            np.savez(labels / f"ep_{i}.npz", **ep)
            fixed.append((obs, cands[:, 1] - f))
        (labels / "ep_2.tmp.npz").write_bytes(b"")  # an abandoned episode: not a label
        report = distil.fit(tmp_path, scale=0.6, margin=0.0, epochs=400, seed=0,
                            models=tmp_path / "model")  # fmt: skip
        assert report["train_states"] == 6 and report["train_mse"] < 0.1 * report["train_zero_mse"]
        pol = load_policy(tmp_path / "model" / f"{distil.NAME}.zip", env=env)
        assert pol.scale == 0.6 and pol.base is not None
        o = pol.vecnormalize.normalize_obs(fixed[0][0][:1])
        residual, _ = pol.model.predict(o, deterministic=True)
        assert residual.ravel() == pytest.approx(fixed[0][1][0] / 0.6, abs=0.1)
    finally:
        env.close()


def _nap(seconds: float) -> float:
    import time

    if seconds < 0:
        raise ValueError("negative nap")
    time.sleep(seconds)
    return seconds


def test_run_until_yields_what_finishes_and_abandons_the_rest_at_the_deadline() -> None:
    import time

    t0 = time.perf_counter()
    # two quick tasks, then one that would hold a worker for 10 minutes; the deadline
    # leaves a busy machine ample time to start the pool and run the quick ones
    got = list(distil.run_until(_nap, [0.01, 0.02, 600.0], 2, t0 + 30.0))
    assert sorted(got) == [0.01, 0.02]
    assert time.perf_counter() - t0 < 300.0  # the long task was terminated, not awaited
    with pytest.raises(ValueError, match="negative nap"):
        list(distil.run_until(_nap, [-1.0], 1, time.perf_counter() + 60.0))


def test_a_label_directory_holds_one_oracle(tmp_path: Path) -> None:
    """Labels of two oracles are never mixed: a resume with another --horizon or
    --confirm is refused before any episode runs, and so is one over labels made before
    the options (full rollouts) or over an unreadable record."""
    deadline = 0.0  # nothing is labelled: only the check runs
    assert distil.label(tmp_path, 0, 0, [0.2], ["straight"], 1, deadline, horizon=5) == []
    record = json.loads((tmp_path / "labels/oracle.json").read_text())
    assert record == {"horizon": 5, "confirm": False}
    assert distil.label(tmp_path, 0, 0, [0.2], ["straight"], 1, deadline, horizon=5) == []
    with pytest.raises(SystemExit, match="horizon 5 and confirm False, not horizon None"):
        distil.label(tmp_path, 0, 0, [0.2], ["straight"], 1, deadline)
    with pytest.raises(SystemExit, match="not horizon 5 and confirm True"):
        distil.label(tmp_path, 0, 0, [0.2], ["straight"], 1, deadline, horizon=5, confirm=True)
    # a record written before --confirm existed is read as confirm False
    (tmp_path / "labels/oracle.json").write_text(json.dumps({"horizon": 5}))
    assert distil.label(tmp_path, 0, 0, [0.2], ["straight"], 1, deadline, horizon=5) == []
    old = tmp_path / "old"
    (old / "labels").mkdir(parents=True)
    (old / "labels/ep_0.npz").write_bytes(b"")
    with pytest.raises(SystemExit, match="horizon None and confirm False, not horizon 5"):
        distil.label(old, 0, 0, [0.2], ["straight"], 1, deadline, horizon=5)
    for bad in ("{", "[5]"):
        (tmp_path / "labels/oracle.json").write_text(bad)
        with pytest.raises(SystemExit, match="unreadable"):
            distil.label(tmp_path, 0, 0, [0.2], ["straight"], 1, deadline, horizon=5)


def test_distil_refuses_a_negative_horizon(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        distil.main(["--horizon", "-1", "--out", "unused"])
    assert exc.value.code == 2 and "argument --horizon: must be >= 0" in capsys.readouterr().err
