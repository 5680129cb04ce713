"""Make ``docs/replay_frame.png``: the top view of a recorded ``CNTDeposit-v0`` episode.

A small rod (Hbar 30, the test suite's configuration), a target of the ``arc``
family, seed 1, 300 steps of a simple heuristic (flow towards the fourth target point
ahead of the contact point). The episode is recorded with
:class:`cnt_env.replay.RerunRecorder` (``.rrd`` and episode ``.npz`` in ``--outdir``)
and its last frame drawn with :func:`cnt_env.replay.render_top_view`; ``--gif`` (or
``.mp4``) also writes the whole episode as a video (:func:`cnt_env.replay.write_video`,
the ``[video]`` extra), every ``--every``-th step.

    python docs/replay_frame.py [--outdir runs/replay_frame] [--png docs/replay_frame.png]
        [--gif runs/replay_frame/episode.gif] [--every 3]
    rerun runs/replay_frame/readme-s1-e0000.rrd
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium
import numpy as np

import cnt_env  # noqa: F401  (registers CNTDeposit-v0)
from cnt_env.replay import RerunRecorder, render_top_view, write_video

SMALL = dict(Hbar=30.0, Ibar=200.0, initial_radius=4.0, warmup_length=3.0,
             control_interval=15.0, reset_advance=2.0, sim_options={"dt_factor": 0.05})  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--outdir", default="runs/replay_frame")
    parser.add_argument("--png", default=str(Path(__file__).with_suffix(".png")))
    parser.add_argument("--target", default="arc")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--gif", default=None, help="also write the episode as a .gif or .mp4")
    parser.add_argument("--every", type=int, default=3, help="video: every n-th step")
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
    if args.gif:
        video = write_video(env.episode_paths[0], args.gif, fps=10, every=args.every)
        print(f"wrote {video}")
    print(f"open the recording with: rerun {env.paths[0]}")


if __name__ == "__main__":
    main()
