"""cnt_env: carbon-nanotube deposition with discrete elastic rods, as a Gymnasium env.

The simulator runs in the dimensionless units of ``cnt_env.units``; SI appears
only there and at the command line (``cnt-sim``, also ``python -m cnt_env``).

Importing the package registers ``CNTDeposit-v0`` with Gymnasium through an entry-point
string, so that numba and the simulator load only when an env is made.
"""

__version__ = "0.1.0"

from gymnasium.envs.registration import register as _register
from gymnasium.envs.registration import registry as _registry

#: Outer TimeLimit cap of ``CNTDeposit-v0``, in control steps. The thin task lays ~1 L_vb
#: of trace per step (400 steps: about 4 periods of the baseline serpentine); route
#: episodes end earlier, at the per-route ``env.max_episode_steps`` (docs/task.md).
MAX_EPISODE_STEPS = 400

if "CNTDeposit-v0" not in _registry:
    _register(
        id="CNTDeposit-v0",
        entry_point="cnt_env.task.env:CNTDepositEnv",
        max_episode_steps=MAX_EPISODE_STEPS,
    )

__all__ = ["MAX_EPISODE_STEPS", "__version__"]
