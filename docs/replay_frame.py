"""Make ``docs/replay_frame.png``: the top view of a recorded ``CNTDeposit-v0`` episode.

A small rod (Hbar 30, the test suite's configuration), a target of the ``arc``
family, seed 1, 300 steps of a simple heuristic (flow towards the fourth target point
ahead of the contact point). The episode is recorded with
:class:`cnt_env.replay.RerunRecorder` (``.rrd`` and episode ``.npz`` in ``--outdir``)
and its last frame drawn with :func:`cnt_env.replay.render_top_view`.

    python docs/replay_frame.py [--outdir runs/replay_frame] [--png docs/replay_frame.png]
    rerun runs/replay_frame/readme-s1-e0000.rrd
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium
import numpy as np

import cnt_env  # noqa: F401  (registers CNTDeposit-v0)
from cnt_env.replay import RerunRecorder, render_top_view

SMALL = dict(Hbar=30.0, Ibar=200.0, initial_radius=4.0, warmup_length=3.0,
             control_interval=15.0, reset_advance=2.0, sim_options={"dt_factor": 0.05})  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outdir", default="runs/replay_frame")
    parser.add_argument("--png", default=str(Path(__file__).with_suffix(".png")))
    parser.add_argument("--target", default="arc")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args(argv)

    env = gymnasium.make("CNTDeposit-v0", max_episode_steps=args.steps, **SMALL)
    env = RerunRecorder(env, args.outdir, tag="readme", save_episodes=True)
    obs, _ = env.reset(seed=args.seed, options={"target": args.target})
    ahead = env.unwrapped.observation_slices["target"]
    while True:
        point = obs[ahead].reshape(-1, 2)[3]  # (x, z) relative to the contact point
        action = (point / max(float(np.linalg.norm(point)), 1e-9)).astype(np.float32)
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    env.close()
    png = render_top_view(env.episode_paths[0], args.png)
    print(f"score {info['score']:.3f}; wrote {env.paths[0]}, {env.episode_paths[0]}, {png}")
    print(f"open the recording with: rerun {env.paths[0]}")


if __name__ == "__main__":
    main()
