"""The RL task on top of the simulator: ``CNTDeposit-v0`` and what it is made of.

* ``env``: the Gymnasium class (translates actions, observations and rewards only);
* ``spaces``: the action map both ways and the vector observation's layout;
* ``scoring``: the agreement score, incremental (env) and batch (constant-flow search);
* ``raster``: the image observation and ``render()``;
* ``routes``: circuit routes (corridor, pads, keep-outs), their families and held-out set
  (the default task, docs/task.md);
* ``targets``: thin target polylines (the v0 task, ``score="thin"``) and polyline helpers;
* ``settings``: validation of the env's keywords.

``CNTDepositEnv`` is imported lazily, so that ``import cnt_env`` stays light.
"""

from typing import Any

__all__ = ["CNTDepositEnv"]


def __getattr__(name: str) -> Any:
    if name == "CNTDepositEnv":
        from cnt_env.task.env import CNTDepositEnv

        return CNTDepositEnv
    raise AttributeError(f"module 'cnt_env.task' has no attribute {name!r}")
