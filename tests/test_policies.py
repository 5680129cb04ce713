"""Baseline policies: the shared interface, the flow <-> action inverse, the offline
score of the constant-flow search against the env's own, the scripted heuristic's
direction and speed rule, and the SB3 loader on the pretrained models."""

from __future__ import annotations

import math

import gymnasium
import numpy as np
import pytest

from cnt_env.task import targets as T
from cnt_env.task.env import flow_from_action
from policies import (
    PRETRAINED_DIR,
    ConstantPolicy,
    Policy,
    RandomPolicy,
    RouteFollower,
    ScriptedPolicy,
    action_from_flow,
    load_policy,
)
from policies.constant import record_constant, score_trace
from policies.scripted import amplitude_curve
from tests.smallrod import small

# A small, fast env. Sliding "B" (x fixed at touchdown): under the default "C" laid nodes
# still move in x until they snap, and the env's monotone score terms (coverage, furthest
# point) then differ from an offline score of the final trace by design.
SMALL = small(score="thin", sliding="B")


# warm states in a temporary cache, whatever a test forgets to pass (tests/conftest.py)
pytestmark = pytest.mark.usefixtures("temp_warm_cache")


@pytest.mark.parametrize("vbar", [0.0, 0.02, 0.065, 0.13])
@pytest.mark.parametrize("phi", np.linspace(-math.pi, math.pi, 9)[:-1].tolist())
def test_action_from_flow_inverts_the_env_map(vbar: float, phi: float) -> None:
    a = action_from_flow(vbar, phi, 0.13)
    assert a.dtype == np.float32 and np.all(np.abs(a) <= 1.0)
    v, p = flow_from_action(a, 0.13)
    assert v == pytest.approx(vbar, abs=1e-6)
    if vbar > 0:
        assert math.remainder(p - phi, 2 * math.pi) == pytest.approx(0.0, abs=1e-5)


def test_interface_and_random_seeding() -> None:
    obs = np.zeros(81, dtype=np.float32)
    rnd = RandomPolicy()
    for pol in (rnd, ConstantPolicy(0.05, 1.0, 0.13), ScriptedPolicy(slice(32, 64), 0.13)):
        assert isinstance(pol, Policy)
        pol.reset(0)
        assert pol.act(obs).shape == (2,)
    rnd.reset(5)
    first = [rnd.act(obs) for _ in range(3)]
    rnd.reset(5)
    assert np.array_equal(first, [rnd.act(obs) for _ in range(3)])


def test_scripted_points_along_the_target_and_slows_for_wide_targets() -> None:
    pol = ScriptedPolicy(slice(0, 32), 0.13)
    ahead = np.column_stack([np.zeros(16), 2.0 * np.arange(1, 17)])  # straight along +z
    vbar, phi = flow_from_action(pol.act(ahead.ravel()), 0.13)
    assert phi == pytest.approx(math.pi / 2, abs=1e-5)
    v, a, _ = amplitude_curve()
    assert vbar == pytest.approx(v[np.argmin(a)], rel=1e-4)  # straight: smallest amplitude
    assert pol.speed_for(float(a.max())) <= pol.speed_for(float(a.min()))


def _constant_episode(env: gymnasium.Env, target: object) -> dict:
    env.reset(seed=2, options={"target": target})
    pol = ConstantPolicy(0.1, 0.7, env.unwrapped.vbar_max)
    for _ in range(30):
        _, _, term, trunc, info = env.step(pol.act(None))
        if term or trunc:
            break
    return info


def test_offline_score_matches_the_env() -> None:
    """The constant-flow search scores one recorded trace offline against every target;
    it must give the env's own score of that flow, to the last bit (thin targets)."""
    env = gymnasium.make("CNTDeposit-v0", max_episode_steps=30, **SMALL)
    ct = record_constant(env, 0.1, 0.7, seed=2, max_steps=30)
    base = env.unwrapped
    for name in ("jog", "s_curve"):
        off = score_trace(ct.trace, T.held_out(name).points, base.tolerance,
                          tuple(base.weights), ct.n_after_step)  # fmt: skip
        info = _constant_episode(env, name)
        for k in ("score", "coverage", "precision", "progress"):
            assert off[k] == info[k], k
    env.close()


def test_offline_route_score_matches_the_env() -> None:
    """The same for routes (``score_route_trace``), with pads, a keep-out and trace
    outside the corridor. The trace is taken relative to the contact point at reset: the
    node laid last before it still slides (sliding B, along z), and measuring from its
    final position shifted the offline trace against the env's route."""
    from cnt_env.task import routes
    from cnt_env.task.scoring import score_route_trace

    env = gymnasium.make("CNTDeposit-v0", max_episode_steps=30, **{**SMALL, "score": "corridor"})
    ct = record_constant(env, 0.1, 0.7, seed=2, max_steps=30)
    cases = [
        {"waypoints": [[0, 0], [12, 0], [12, 12]], "width": 3.0,
         "pads": [[[6, -2], [6, 2]]], "keepouts": [{"rect": [3, 2.5, 8, 6]}]},
        {"waypoints": [[0, 0], [20, 20]], "width": 2.0},
    ]  # fmt: skip
    precisions = []
    for case in cases:
        route = routes.from_dict(case)
        off = score_route_trace(ct.trace, route, ct.n_after_step)
        info = _constant_episode(env, route)
        for k in ("score", "coverage", "precision", "progress", "shorts", "completed"):
            assert off[k] == info[k], k
        precisions.append(info["precision"])
    assert min(precisions) < 0.6  # the diagonal's trace is mostly outside its corridor
    env.close()


@pytest.mark.skipif(not (PRETRAINED_DIR / "ppo.zip").is_file(), reason="no pretrained models")
@pytest.mark.parametrize("name", ["ppo", "sac", "ppo_residual"])
def test_pretrained_models_load_with_their_normalisation(name: str) -> None:
    import gymnasium as gym

    from training.common import env_settings, load_config

    env_kwargs, _ = env_settings(load_config(PRETRAINED_DIR / f"{name}.yml"))
    env = gym.make("CNTDeposit-v0", **env_kwargs)
    n_obs = env.observation_space.shape[0]
    pol = load_policy(PRETRAINED_DIR / f"{name}.zip", env=env)
    if name == "ppo_residual":  # its base follower reads the route of the env it acts in
        assert pol.base._env is env.unwrapped
        with pytest.warns(UserWarning, match="pass env="):
            assert load_policy(PRETRAINED_DIR / f"{name}.zip").base._env is not env.unwrapped
    # the statistics and the network fit the env the model's own config makes
    assert pol.vecnormalize is not None and pol.vecnormalize.obs_rms.mean.shape == (n_obs,)
    assert pol.model.observation_space.shape == (n_obs,)
    assert (pol.base is not None) == (name == "ppo_residual")
    obs = np.zeros(n_obs, dtype=np.float32)
    obs[32:64] = np.column_stack([2.0 * np.arange(1, 17), np.zeros(16)]).ravel()
    a = pol.act(obs)
    assert a.shape == (2,) and np.all(np.abs(a) <= 1.0)


def test_constant_search_on_routes_scores_with_the_env_score() -> None:
    from cnt_env.task import routes
    from cnt_env.task.scoring import score_route_trace
    from policies.constant import ConstantTrace, search

    u = routes.held_out("u_turn")
    along = T.resample(u.waypoints, 1.0)[0]
    off = along + np.array([0.0, -40.0])  # parallel but outside the corridor
    n = np.arange(10, len(along) + 10, 10).clip(max=len(along))
    traces = [ConstantTrace(0.1, 0.0, 0, along, n), ConstantTrace(0.13, 1.0, 0, off, n)]
    best, rows = search(traces, ["u_turn"], 2.0, score="corridor", step_limits={"u_turn": 5})
    assert best["u_turn"]["vbar"] == 0.1
    cut = score_route_trace(along, u, n[:5])  # cut at the route's episode length
    assert best["u_turn"]["score"] == pytest.approx(cut["score"]) and cut["progress"] < 1.0
    assert {r["vbar"] for r in rows} == {0.1, 0.13}


def test_route_follower_steers_the_centre_along_the_route() -> None:
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    layout = ObservationLayout(16, 16, (2.0, 8.0, 77.5, 155.0), route=True)
    pol = RouteFollower(layout.slices, 0.13)
    obs = np.zeros(layout.size)
    sl = layout.slices
    # the band's centre 5 L_vb below the contact point, the route ahead along +x at z = 0
    obs[sl["trace"]] = np.column_stack([np.linspace(-20, 0, 16), np.full(16, -5.0)]).ravel()
    obs[sl["target"]] = np.column_stack([2.0 * np.arange(1, 17), np.zeros(16)]).ravel()
    obs[sl["route"]] = [15.0, 1000.0, 1000.0]  # no keep-out
    vbar, phi = flow_from_action(pol.act(obs), 0.13)
    assert vbar == pytest.approx(0.13, rel=1e-4)  # the narrowest band fits w = 15
    assert 0.0 < phi < math.pi / 4  # ahead, and back up toward the route's line
    obs[sl["route"]] = [15.0, 0.0, -12.0]  # a keep-out just below the centre
    _, phi_k = flow_from_action(pol.act(obs), 0.13)
    assert phi_k > phi  # pushed away from it
    # the fastest flow drifts fastest and lays the narrowest band: every corridor gets it
    assert pol.speed_for(40.0) == pol.speed_for(10.0) == 0.13


def test_plan_around_moves_the_route_off_a_keep_out_by_the_reach() -> None:
    from policies.route_follower import plan_around

    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    pts = np.array([[5.0, 13.0], [5.0, 5.0], [11.0, 5.0], [5.0, 40.0], [13.0, 13.0]])
    reach = np.array([2.0, 6.0])  # (x, z): the band is wider across the steps
    out = plan_around(pts, (square,), reach)
    # above the top edge: to 6 along z; right of it: to 2 along x
    assert out[0] == pytest.approx([5.0, 16.0])
    assert out[2] == pytest.approx([12.0, 5.0])
    assert out[3] == pytest.approx(pts[3])  # far away: untouched
    # inside, at the centre: out through the nearest edge (a tie: the first, z = 0)
    assert out[1] == pytest.approx([5.0, -6.0])
    # past a corner: along the diagonal to |n| . reach from the corner
    n = np.array([1.0, 1.0]) / math.sqrt(2.0)
    assert out[4] == pytest.approx(np.array([10.0, 10.0]) + (n @ reach) * n)
    # idempotent: a planned route is already clear
    assert plan_around(out, (square,), reach) == pytest.approx(out)
    # on the boundary (a route along the edge, which may touch it): out along the edge's
    # normal, as from just outside it (it stayed where it was: no direction at distance 0)
    on_edge = np.array([[5.0, 10.0], [10.0, 3.0], [0.0, 0.0]])
    out = plan_around(on_edge, (square,), reach)
    assert out[0] == pytest.approx([5.0, 16.0]) and out[1] == pytest.approx([12.0, 3.0])
    assert out[2] == pytest.approx([0.0, -6.0])  # a corner: a tie, the first edge (z = 0)


def test_route_follower_plan_only_acts_where_there_are_keep_outs() -> None:
    """On a route without keep-outs the (default) planning follower's actions equal the
    plain one's; with a keep-out in the way, the plan steers further from it."""
    from cnt_env.task import routes
    from policies import RouteFollower

    env = gymnasium.make("CNTDeposit-v0", score="corridor")
    try:
        obs, _ = env.reset(seed=0, options={"target": "u_turn"})
        a = RouteFollower.from_env(env).act(obs)
        b = RouteFollower.from_env(env, plan=False).act(obs)
        assert np.array_equal(a, b)
        # a keep-out just above the straight route's line, 30 L_vb ahead
        block = {"waypoints": [[0, 0], [120, 0]], "width": 15.0,
                 "keepouts": [{"rect": [20, 8, 60, 40]}]}  # fmt: skip
        obs, _ = env.reset(seed=0, options={"target": block})
        assert isinstance(env.unwrapped.target, routes.Route)
        # the follower's own first flow (the start flow ignores the plan: start_flow)
        follower = RouteFollower.from_env(env, start_swing=False)
        flat = RouteFollower.from_env(env, plan=False, start_swing=False)
        _, phi_plan = flow_from_action(follower.act(obs), 0.13)
        _, phi_flat = flow_from_action(flat.act(obs), 0.13)
        assert phi_plan < phi_flat  # turned down, away from the block
    finally:
        env.close()


def test_route_follower_centre_is_the_midpoint_of_its_last_windows() -> None:
    """With the contact known in the route's frame the centre is the midpoint of the
    extent of the last ``memory`` trace windows (not the mean of the latest one, which
    swings with the pattern's phase); without it, or with memory 0, the window's mean."""
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    layout = ObservationLayout(4, 4, (2.0,), route=True)
    # one swing of a band: mostly at the top (z = 10), one point at the bottom (z = -30)
    w1 = np.array([[-6.0, 10.0], [-4.0, 10.0], [-2.0, 10.0], [-1.0, -30.0]])
    w2 = np.array([[-6.0, 8.0], [-4.0, 9.0], [-2.0, 10.0], [-1.0, 12.0]])
    pol = RouteFollower(layout.slices, 0.13, memory=2)
    assert pol.pattern_centre(w1, None) == pytest.approx(w1.mean(axis=0))
    assert pol.pattern_centre(w1, np.zeros(2)) == pytest.approx([-3.5, -10.0])
    # the contact moved 10 along x: both windows in the route's frame, back relative
    c = pol.pattern_centre(w2, np.array([10.0, 0.0]))
    assert c == pytest.approx([0.5 * (-6.0 + 9.0) - 10.0, -9.0])
    c = pol.pattern_centre(w2, np.array([20.0, 0.0]))  # the first window has left
    assert c == pytest.approx([0.5 * (4.0 + 19.0) - 20.0, 10.0])
    flat = RouteFollower(layout.slices, 0.13, memory=0)
    assert flat.pattern_centre(w1, np.zeros(2)) == pytest.approx(w1.mean(axis=0))
    with pytest.raises(ValueError, match="memory"):
        RouteFollower(layout.slices, 0.13, memory=-1)


def test_route_follower_leads_the_centre_by_its_last_displacement() -> None:
    """The predicted centre is the centre plus ``lead`` times its displacement over the
    last control step, measured in the route's frame (the contact point moves between
    steps); the first step of a route, no route, or lead 0 give the centre itself."""
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    layout = ObservationLayout(4, 4, (2.0,), route=True)
    pol = RouteFollower(layout.slices, 0.13, lead=2.0)
    c0, c1 = np.array([-3.0, 1.0]), np.array([-2.0, 4.0])
    assert pol.predicted_centre(c0, np.array([10.0, 0.0])) == pytest.approx(c0)
    # in the route's frame the centre went from (7, 1) to (13, 4): moved (6, 3)
    got = pol.predicted_centre(c1, np.array([15.0, 0.0]))
    assert got == pytest.approx(c1 + 2.0 * np.array([6.0, 3.0]))
    assert pol.predicted_centre(c1, None) == pytest.approx(c1)
    still = RouteFollower(layout.slices, 0.13, lead=0.0)
    still.predicted_centre(c0, np.zeros(2))
    assert still.predicted_centre(c1, np.zeros(2)) == pytest.approx(c1)
    for bad in (-1.0, math.nan):
        with pytest.raises(ValueError, match="lead"):
            RouteFollower(layout.slices, 0.13, lead=bad)


def test_route_follower_leads_a_run_by_run_lead() -> None:
    """``run_lead``: while the pen lays a run (``_run``) the centre is led by ``run_lead``
    control steps, otherwise by ``lead``; None (the default) is ``lead`` itself."""
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    slices = ObservationLayout(4, 4, (2.0,), route=True).slices
    moved = np.array([0.0, 17.0])

    def led(run: bool, **kw) -> np.ndarray:
        pol = RouteFollower(slices, 0.13, lead=1.0, **kw)
        pol._run = run
        pol.predicted_centre(np.zeros(2), np.zeros(2))
        return pol.predicted_centre(np.zeros(2), moved)

    assert led(True, run_lead=3.0) == pytest.approx(3.0 * moved)
    assert led(False, run_lead=3.0) == pytest.approx(moved)
    assert led(True) == pytest.approx(moved)
    assert led(True, run_lead=0.0) == pytest.approx([0.0, 0.0])
    for bad in (-1.0, math.inf):
        with pytest.raises(ValueError, match="run_lead"):
            RouteFollower(slices, 0.13, run_lead=bad)


def test_route_follower_plan_band_is_the_widest_of_the_route_or_of_recent_steps() -> None:
    """``plan_band``: with ``band_memory`` 0 the plan keeps clear of the widest band seen
    on the route (it only widens); with n > 0, of the widest of the last n steps."""
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    slices = ObservationLayout(4, 4, (2.0,), route=True).slices
    halves = [[1.0, 40.0], [9.0, 20.0], [3.0, 18.0], [2.0, 21.0]]
    for memory, want in ((0, [9.0, 40.0]), (2, [3.0, 21.0]), (3, [9.0, 21.0])):
        pol = RouteFollower(slices, 0.13, band_memory=memory)
        for h in halves:
            pol._half = got = pol.plan_band(np.array(h))
        assert got == pytest.approx(want)
    with pytest.raises(ValueError, match="band_memory"):
        RouteFollower(slices, 0.13, band_memory=-1)


def test_route_follower_steers_a_run_by_its_contact_point() -> None:
    """``run_centre``: after that many flows within 30° of the same one of ±z the pen
    lays a run, whose centre is its contact point (zeros), not the midpoint of the
    windows; a flow across or diagonal to the steps, flows of both signs, too few flows,
    no route, or ``run_centre`` 0 keep the band's centre. A switch clears the drift the
    next prediction would add."""
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    slices = ObservationLayout(4, 4, (2.0,), route=True).slices
    band = np.array([-3.0, 12.0])
    contact = np.array([5.0, 40.0])

    def steered(phis: list[float], run_centre: int = 2, at=contact) -> np.ndarray:
        pol = RouteFollower(slices, 0.13, run_centre=run_centre)
        pol._phis.extend(phis)
        return pol.run_centre_or(band, at)

    up, down = math.pi / 2, -math.pi / 2
    assert steered([up, up]) == pytest.approx([0.0, 0.0])
    assert steered([down, down + math.radians(25.0)]) == pytest.approx([0.0, 0.0])
    assert steered([up, up], run_centre=1) == pytest.approx([0.0, 0.0])
    assert steered([up]) == pytest.approx(band)  # one flow of the two
    assert steered([up, down]) == pytest.approx(band)  # both signs: a swing, not a run
    assert steered([up, math.radians(55.0)]) == pytest.approx(band)  # 35° off the steps
    assert steered([0.0, 0.0]) == pytest.approx(band)  # across the steps: a band
    assert steered([up, up], at=None) == pytest.approx(band)  # no route
    assert steered([up, up], run_centre=0) == pytest.approx(band)
    # the switch: the centre jumps from the band's line to the contact, no drift added
    pol = RouteFollower(slices, 0.13, run_centre=1, lead=1.0)
    pol.predicted_centre(pol.run_centre_or(band, contact), contact)
    pol._phis.append(up)
    got = pol.predicted_centre(pol.run_centre_or(band, contact), contact + np.array([0.0, 17.0]))
    assert got == pytest.approx([0.0, 0.0])
    with pytest.raises(ValueError, match="run_centre"):
        RouteFollower(slices, 0.13, run_centre=-1)


def test_route_follower_keeps_a_run_until_its_flow_leaves_run_exit() -> None:
    """``run_exit``: a run, once laid, goes on while the last flow stays within
    ``run_exit`` degrees of the steps' axis; a new run still needs flows within 30°. At 30
    (the entry's angle) a flow 45° off ends it, the next step steers the band's centre."""
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    slices = ObservationLayout(4, 4, (2.0,), route=True).slices
    band, contact = np.array([-3.0, 12.0]), np.array([5.0, 40.0])
    down = -math.pi / 2

    def run_after(phis: list[float], run_exit: float) -> list[bool]:
        pol = RouteFollower(slices, 0.13, run_centre=1, run_exit=run_exit)
        out = []
        for phi in phis:
            pol._phis.append(phi)
            out.append(bool(np.all(pol.run_centre_or(band, contact) == 0.0)))
        return out

    d45, d55, d70 = (down + math.radians(a) for a in (45.0, 55.0, 70.0))
    assert run_after([down, d45, down, d45], 30.0) == [True, False, True, False]
    assert run_after([down, d45, down, d45], 50.0) == [True, True, True, True]
    assert run_after([down, d45, d55], 50.0) == [True, True, False]
    assert run_after([d45, d45], 50.0) == [False, False]  # entry still needs 30°
    assert run_after([down, d70], 60.0) == [True, False]
    for bad in (29.0, 90.0, float("nan")):
        with pytest.raises(ValueError, match="run_exit"):
            RouteFollower(slices, 0.13, run_exit=bad)


def test_route_follower_unhooks_a_run_that_goes_against_the_flow() -> None:
    """``hooked``: the last flow within 30° of the steps (±z) and the contact ran along
    them against it by more than ``hook_tol``; then the flow turns ``unhook`` off the
    aim. A contact moving with the flow or across the steps, by less than the tolerance,
    or after a flow across or diagonal to the steps (a serpentine's swing) is not
    hooked; without the route (no contact) or with unhook 0 nothing is checked."""
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    layout = ObservationLayout(4, 4, (2.0,), route=True)

    def after(step: list[float], phi: float = math.pi / 2, **kw) -> bool:
        pol = RouteFollower(layout.slices, 0.13, **kw)
        pol._played = phi  # the last flow played (default: along +z)
        assert not pol.hooked(np.array([5.0, 10.0]))  # the first contact: nothing to compare
        return pol.hooked(np.array([5.0, 10.0]) + np.array(step))

    assert after([0.0, -3.0])  # 3 L_vb upstream
    assert after([1.0, -3.0])  # mostly along the steps
    assert after([0.0, 3.0], phi=-math.pi / 2)  # upstream of a flow along -z
    assert after([0.0, -3.0], phi=math.radians(65.0))  # within 30° of the steps
    assert not after([0.0, 3.0])  # with the flow
    assert not after([3.0, -3.0])  # across the steps as much as along
    assert not after([0.0, -3.0], phi=math.pi / 4)  # a diagonal flow's serpentine swing
    assert not after([0.0, -3.0], phi=0.0)  # a flow across the steps
    assert not after([0.0, -1.5])  # within hook_tol = 2
    assert after([0.0, -1.5], hook_tol=1.0)
    assert not after([0.0, -3.0], unhook=0.0)
    assert not RouteFollower(layout.slices, 0.13).hooked(None)
    for bad in (2.0, math.nan):
        with pytest.raises(ValueError, match="unhook"):
            RouteFollower(layout.slices, 0.13, unhook=bad)
    with pytest.raises(ValueError, match="hook_tol"):
        RouteFollower(layout.slices, 0.13, hook_tol=-1.0)


def test_the_hook_test_after_the_start_flow_uses_the_flow_played() -> None:
    """The first step of a route plays the start flow, not the follower's own: the next
    step's hook test must compare the contact's motion with the start flow. (It compared
    it with the follower's own flow, here ~170° away, and took the run laid with the
    start flow along +z for a run hooked against a flow along -z: a false unhook.)"""
    from policies import RouteFollower

    env = gymnasium.make("CNTDeposit-v0", drag_law="printed", delta_bar=1.0)
    base = env.unwrapped
    obs, _ = env.reset(seed=3, options={"target": {"waypoints": [[0, 0], [0, -100]]}})
    pol = RouteFollower.from_env(env)
    pol.reset(3)
    checks: list[bool] = []
    hooked = pol.hooked
    pol.hooked = lambda contact: checks.append(hooked(contact)) or checks[-1]
    action = pol.act(obs)
    played, own = flow_from_action(action, base.vbar_max)[1], pol._phis[-1]
    assert math.sin(played) > 0.9 and math.sin(own) < -0.9  # +z played, -z intended
    z0 = base.sim.trace()[-1, 2]
    obs, *_ = env.step(action)
    assert base.sim.trace()[-1, 2] - z0 > 3 * pol.hook_tol  # a run along +z, with the flow
    pol.act(obs)
    assert checks == [False, False]
    env.close()


def test_the_follower_starts_each_episode_afresh_even_on_the_same_route_object() -> None:
    """Its per-route memory (band windows, start flow, previous centre) was keyed on the
    Route object only: an episode on the same Route without ``policy.reset()`` carried
    the last episode's state. The env's ``episode_index`` tells the episodes apart."""
    from cnt_env.task.routes import held_out
    from policies import RouteFollower

    env = gymnasium.make("CNTDeposit-v0", drag_law="printed", delta_bar=1.0)
    route = held_out("u_turn")
    pol = RouteFollower.from_env(env)
    obs, _ = env.reset(seed=0, options={"target": route})
    pol.reset(0)
    index = env.unwrapped.episode_index
    for _ in range(4):
        obs, *_ = env.step(pol.act(obs))
    obs, _ = env.reset(seed=5, options={"target": route})
    assert env.unwrapped.episode_index == index + 1
    stale = pol.act(obs)  # no pol.reset()
    fresh = RouteFollower.from_env(env)
    obs, _ = env.reset(seed=5, options={"target": route})
    assert np.array_equal(stale, fresh.act(obs))
    env.close()


def test_route_follower_unhooks_away_from_the_steps_axis() -> None:
    """``unhook_turn``: with ``unhook_away`` (the default) the flow
    turns away from ±z toward the side it leans to, so its across-step part grows in all
    four quadrants, and a flow exactly along ±z turns counter-clockwise."""
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    slices = ObservationLayout(4, 4, (2.0,), route=True).slices
    ccw = RouteFollower(slices, 0.13, unhook=0.5, unhook_away=False)
    away = RouteFollower(slices, 0.13, unhook=0.5)  # the default: away
    for deg in (66.0, 114.0, -66.0, -114.0, 90.0, -90.0):
        phi = math.radians(deg)
        assert ccw.unhook_turn(phi) == 0.5
        turned = phi + away.unhook_turn(phi)
        if abs(abs(deg) - 90.0) > 1e-9:
            assert abs(math.cos(turned)) > abs(math.cos(phi))  # further off the steps
        else:
            assert turned == pytest.approx(phi + 0.5)
    turned = math.degrees(math.radians(66.0) + away.unhook_turn(math.radians(66.0)))
    assert turned == pytest.approx(66.0 - math.degrees(0.5))  # 66° -> 37°


def test_start_flow_answers_the_warm_swing_by_its_phase() -> None:
    """``start_flow``: a window that is one straight swing along the steps (the swing's
    end) gets a flow 30° off its heading, upstream of the warm flow; a window that shows
    the swing's U-turn (under way) a flow against its heading. Mirror images in z and in
    the warm flow's x give mirrored flows; a route leading along the steps against the
    heading gets none."""
    from policies.route_follower import start_flow

    z = np.linspace(64.0, 4.0, 16)
    straight = np.column_stack([np.zeros(16), z])  # heading -z, one straight swing
    theta = np.linspace(-0.7, np.pi / 2, 16)  # up to the U-turn's cap, then down
    turn = np.column_stack([-4.4 * np.sin(theta), 4.0 + 45.0 * np.cos(theta)])
    downstream = np.array([0.28, 0.0])  # the warm flow along +x
    across, up, down = np.array([1.0, 0.0]), np.array([0.0, 1.0]), np.array([0.0, -1.0])

    def deg(window: np.ndarray, flow=downstream, lead=across) -> float | None:
        phi = start_flow(window, flow, lead)
        return None if phi is None else math.degrees(phi)

    assert deg(straight) == pytest.approx(-120.0)
    assert deg(straight * [1, -1]) == pytest.approx(120.0)
    assert deg(straight, flow=-downstream) == pytest.approx(-60.0)
    assert deg(turn) == pytest.approx(90.0)  # heading -z
    assert deg(turn * [1, -1]) == pytest.approx(-90.0)
    # a route along the steps against the heading wants the swing's turn: no override;
    # along the heading, or diagonal (45°), it keeps the start flow
    assert deg(straight, lead=up) is None and deg(turn, lead=up) is None
    assert deg(straight * [1, -1], lead=down) is None
    assert deg(straight, lead=down) == pytest.approx(-120.0)
    assert deg(straight, lead=np.array([1.0, 1.0])) == pytest.approx(-120.0)


def test_route_follower_overrides_only_a_routes_first_flow() -> None:
    """``start_swing``: the first act() after a new route gives the start flow at v̄_max;
    the next steps, a follower with the option off and a route that leads along the
    steps against the swing's heading steer as before."""
    from cnt_env.task.routes import Route
    from cnt_env.task.spaces import ObservationLayout
    from policies import RouteFollower

    layout = ObservationLayout(16, 16, (2.0, 8.0, 77.5, 155.0), route=True)
    sl = layout.slices
    obs = np.zeros(layout.size)
    obs[sl["trace"]] = np.column_stack([np.zeros(16), np.linspace(64.0, 4.0, 16)]).ravel()
    obs[sl["target"]] = np.column_stack([2.0 * np.arange(1, 17), np.zeros(16)]).ravel()
    obs[sl["route"]] = [15.0, 1000.0, 1000.0]
    obs[sl["flow"]] = [0.28, 0.0]

    class Env:
        target = Route([(0.0, 0.0), (60.0, 0.0)], width=15.0)

    def flows(**kw) -> list[tuple[float, float]]:
        pol = RouteFollower(sl, 0.13, **kw)
        pol._env = Env()
        return [flow_from_action(pol.act(obs), 0.13) for _ in range(2)]

    on, off = flows(), flows(start_swing=False)
    Env.target = Route([(0.0, 0.0), (0.0, 60.0)], width=15.0)  # leads +z: wants the turn
    assert np.array(flows()) == pytest.approx(np.array(flows(start_swing=False)))
    assert on[0][0] == pytest.approx(0.13, rel=1e-4)
    assert math.degrees(on[0][1]) == pytest.approx(-120.0, abs=1e-3)
    assert on[1] == pytest.approx(off[1])  # the follower's memory saw its own flow
    assert abs(math.degrees(off[0][1]) + 120.0) > 30.0  # the follower's own first flow


def test_algorithm_comes_from_the_name_else_the_config_beside_the_model(tmp_path) -> None:
    """algo_of: an explicit algorithm, else the file name's, else ``run: algo`` of the
    config beside the model (a run's best_model.zip with its yml); neither is a clear
    error naming both places, raised before anything is loaded."""
    from policies.sb3 import algo_of

    assert algo_of(tmp_path / "ppo_residual.zip") == "ppo"
    assert algo_of(tmp_path / "best_model.zip", "sac") == "sac"
    with pytest.raises(ValueError, match=r"best_model\.yml"):
        algo_of(tmp_path / "best_model.zip")
    (tmp_path / "best_model.yml").write_text("CNTDeposit-v0: {}\nrun:\n  algo: sac\n")
    assert algo_of(tmp_path / "best_model.zip") == "sac"
    (tmp_path / "best_model.yml").write_text("run: [unclosed\n")  # corrupt: the same error
    with pytest.raises(ValueError, match="pass the algorithm"):
        algo_of(tmp_path / "best_model.zip")


@pytest.mark.parametrize("score", ["corridor", "thin"])
def test_the_baselines_that_read_the_vector_observation_refuse_an_image(score: str) -> None:
    """The follower and the scripted policy index the vector observation's slices; on the
    image they would read pixels as positions, so they refuse it and say what to do."""
    env = gymnasium.make("CNTDeposit-v0", **small(score=score), obs_mode="image")
    cls = RouteFollower if score == "corridor" else ScriptedPolicy
    with pytest.raises(ValueError, match="obs_mode='vector' or 'dict'"):
        cls.from_env(env)
    cls.from_env(gymnasium.make("CNTDeposit-v0", **small(score=score)))  # the vector: fine


@pytest.mark.parametrize("score", ["corridor", "thin"])
def test_the_baselines_read_the_vector_part_of_a_dict_observation(score: str) -> None:
    """On obs_mode "dict" the follower and the scripted policy read its "vector" part: they
    play the episode they play on the vector observation, action for action."""
    cls = RouteFollower if score == "corridor" else ScriptedPolicy
    target = {"corridor": "u_turn", "thin": "jog"}[score]
    played = {}
    for mode in ("vector", "dict"):
        env = gymnasium.make("CNTDeposit-v0", **small(score=score), obs_mode=mode)
        policy = cls.from_env(env)
        obs, _ = env.reset(seed=4, options={"target": target})
        policy.reset(4)
        actions = []
        for _ in range(6):
            actions.append(policy.act(obs))
            obs, *_ = env.step(actions[-1])
        played[mode] = np.array(actions)
        env.close()
    assert np.array_equal(played["vector"], played["dict"])
    assert np.ptp(played["vector"], axis=0).max() > 0  # it steers: the actions change


def test_an_ensemble_must_observe_one_way(tmp_path) -> None:
    from training.evaluate import observation_settings

    paths = []
    for name, extra in (("a", {}), ("b", {"obs_mode": "image"})):
        (tmp_path / f"{name}.yml").write_text(
            f"CNTDeposit-v0:\n  env_kwargs: {extra or {'pattern_every': 0}}\n"
        )
        paths.append(tmp_path / f"{name}.zip")
    assert observation_settings(paths[:1]) == {}
    assert observation_settings(paths[1:]) == {"obs_mode": "image"}
    assert observation_settings([tmp_path / "none.zip"]) == {}  # no config beside it
    with pytest.raises(ValueError, match="observe differently"):
        observation_settings(paths)
