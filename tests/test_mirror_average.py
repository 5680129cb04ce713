"""mirror_average (policies/sb3.py SB3Policy): a trained agent's action averaged with its
action for the observation's mirror image in z, mirrored back, so the policy is
equivariant under the substrate's z-mirror symmetry."""

from __future__ import annotations

import numpy as np
import pytest

from cnt_env.task.spaces import ACTION_Z_MIRROR
from policies import PRETRAINED_DIR, load_policy
from policies.sb3 import SB3Policy

pytestmark = pytest.mark.usefixtures("temp_warm_cache")
AGENT = PRETRAINED_DIR / "ppo_residual.zip"


class _Model:
    """A deterministic, nonlinear, not equivariant stand-in for an SB3 model."""

    def __init__(self, d: int) -> None:
        self.w = np.random.default_rng(0).normal(size=(d, 2)).astype(np.float32)

    def predict(self, o: np.ndarray, deterministic: bool = True):
        assert deterministic
        return np.tanh(o @ self.w[: o.shape[-1]] + 0.3), None


@pytest.mark.parametrize("n_stack", [1, 3])
def test_the_mirror_average_is_equivariant_and_changes_the_action(n_stack) -> None:
    d = 6
    signs = np.array([1, -1, 1, -1, 1, 1], dtype=np.float32)
    model = _Model(d * n_stack)
    mirrored = SB3Policy(model, frame_stack=n_stack, mirror=lambda o: o * signs)
    plain = SB3Policy(model, frame_stack=n_stack)
    twin = SB3Policy(model, frame_stack=n_stack, mirror=lambda o: o * signs)
    rng = np.random.default_rng(1)
    for p in (mirrored, plain, twin):
        p.reset(0)
    for _ in range(4):  # through the frame stacks, one per view
        o = rng.normal(size=d).astype(np.float32)
        a, m = mirrored.act(o), twin.act(o * signs)
        assert np.array_equal(m, a * ACTION_Z_MIRROR)  # exact: +-1 and a commuted sum
        assert not np.allclose(a, plain.act(o))


@pytest.mark.skipif(not AGENT.is_file(), reason="no pretrained models")
def test_the_config_key_and_the_override_set_it(agent_env) -> None:
    env = agent_env
    assert load_policy(AGENT, env=env).mirror is None  # shipped: off
    on = load_policy(AGENT, env=env, mirror_average=True)
    assert on.mirror == env.unwrapped.layout.z_mirror
    obs, _ = env.reset(seed=3)
    on.reset(3)
    off = load_policy(AGENT, env=env)
    off.reset(3)
    assert not np.array_equal(on.act(obs), off.act(obs))


@pytest.mark.skipif(not AGENT.is_file(), reason="no pretrained models")
def test_mirror_average_needs_the_vector_observations_env() -> None:
    with pytest.raises(ValueError, match="mirror_average needs env="):
        load_policy(PRETRAINED_DIR / "ppo.zip", mirror_average=True)


def test_the_training_wrapper_accepts_the_inference_option() -> None:
    import gymnasium as gym

    from training.common import ResidualAction

    env = gym.make("CNTDeposit-v0", score="corridor", max_episode_steps=2)
    w = ResidualAction(env, scale=1.0, mirror_average=True)
    w.reset(seed=0)
    env.close()


class _EquivariantBase:
    """A base policy that mirrors with the observation: (tanh o0, tanh o1), o1 a z."""

    def __init__(self) -> None:
        self.slices: dict = {}

    def act(self, obs: np.ndarray) -> np.ndarray:
        return np.tanh(np.asarray(obs[:2], dtype=np.float32))

    def reset(self, seed: int | None = None) -> None:
        pass


@pytest.mark.parametrize("observe_base", [False, True])
def test_a_residual_over_an_equivariant_base_is_equivariant(observe_base) -> None:
    """The residual agent's whole action (clip(base + scale * mean)) mirrors with the
    observation when its base does; with ``observe_base`` the base's action, appended to
    the observation, is mirrored in the second view too."""
    d = 6
    signs = np.array([1, -1, 1, -1, 1, 1], dtype=np.float32)
    model = _Model(d + (2 if observe_base else 0))

    def agent() -> SB3Policy:
        return SB3Policy(model, base=_EquivariantBase(), scale=0.8, observe_base=observe_base,
                         mirror=lambda o: o * signs)  # fmt: skip

    a, b = agent(), agent()
    o = np.random.default_rng(2).normal(size=d).astype(np.float32)
    assert np.array_equal(b.act(o * signs), a.act(o) * ACTION_Z_MIRROR)
