"""Callbacks and rl-zoo config conventions of ``cnt-train``.

* :class:`TaskMetrics`: the task's own metrics of every finished training episode
  (``info`` of CNTDeposit-v0: score, coverage, progress, inside, shorts, completion) as
  tensorboard scalars under ``task/``;
* :class:`Curriculum`: from each stage's share of the budget on, the training envs draw
  their routes from that stage's families and difficulty (``CNTDeposit-v0``'s
  ``set_route_draw``, from each env's next reset); tensorboard ``curriculum/stage``;
* :func:`schedule`, :func:`policy_kwargs`: rl-zoo's ``lin_<value>`` schedules and string
  ``policy_kwargs`` ("dict(net_arch=[64, 64])").
"""

from __future__ import annotations

import ast
from typing import Any

__all__ = [
    "TASK_METRICS",
    "make_curriculum",
    "make_task_metrics",
    "policy_kwargs",
    "schedule",
]

#: ``info`` keys of CNTDeposit-v0 logged at each episode's end (those present).
TASK_METRICS = ("score", "coverage", "progress", "precision", "inside", "shorts", "short_length",
                "completed", "is_success", "laid_length")  # fmt: skip


def schedule(value: Any) -> Any:
    """rl-zoo's ``lin_<v>``: a linear schedule from v to 0 over training; else ``value``."""
    if isinstance(value, str) and value.startswith("lin_"):
        start = float(value[4:])

        def linear(progress_remaining: float) -> float:
            return progress_remaining * start

        return linear
    return value


def policy_kwargs(value: Any) -> dict[str, Any]:
    """``policy_kwargs`` as a dict: rl-zoo writes it as a string ``"dict(net_arch=[64])"``
    (read here with ``ast``, no eval: only literal keyword values)."""
    if value is None:
        return {}
    if isinstance(value, dict):
        return dict(value)
    tree = ast.parse(str(value), mode="eval").body
    if not (isinstance(tree, ast.Call) and isinstance(tree.func, ast.Name)
            and tree.func.id == "dict" and not tree.args):  # fmt: skip
        raise ValueError(f"policy_kwargs must read 'dict(key=literal, ...)', got {value!r}")
    return {kw.arg: ast.literal_eval(kw.value) for kw in tree.keywords}


def make_task_metrics():
    """:class:`TaskMetrics` (built lazily: SB3 is imported only when training)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class TaskMetrics(BaseCallback):
        """Mean of :data:`TASK_METRICS` over the episodes finished since the last log."""

        def _on_step(self) -> bool:
            for info, done in zip(self.locals["infos"], self.locals["dones"], strict=True):
                if not done:
                    continue
                for key in TASK_METRICS:
                    if key in info:
                        self.logger.record_mean(f"task/{key}", float(info[key]))
            return True

    return TaskMetrics()


def make_curriculum(stages: list[tuple[int, dict[str, Any]]]):
    """:class:`Curriculum` over ``stages``: ``(timestep, set_route_draw kwargs)`` in
    increasing order (training.common.curriculum_settings, scaled to the budget). Each
    switch is printed (one line a stage)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Curriculum(BaseCallback):
        """Switches the training envs' route draw at each stage's timestep."""

        def __init__(self) -> None:
            super().__init__()
            self.stage = 0  # stages applied so far

        def _on_step(self) -> bool:
            while self.stage < len(stages) and self.num_timesteps >= stages[self.stage][0]:
                draw = stages[self.stage][1]
                self.training_env.env_method("set_route_draw", **draw)
                self.stage += 1
                print(f"curriculum: stage {self.stage} from step {self.num_timesteps}: {draw}")
            self.logger.record("curriculum/stage", self.stage)
            return True

    return Curriculum()
