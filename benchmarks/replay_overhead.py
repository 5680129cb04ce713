"""Per-step cost of the rerun replay wrappers on ``CNTDeposit-v0``.

The same env (same seed, same actions) is stepped bare, inside
:class:`cnt_env.replay.EpisodeSaver` (the arrays only, no rerun), inside
:class:`cnt_env.replay.RerunRecorder` as configured by default for files (arrays
collected per step, the ``.rrd`` written column by column when the episode ends), and
inside ``RerunRecorder(stream=True)`` (every step logged as it happens, as for a live
viewer), ``--repeats`` times each, interleaved.

The wrapper's own cost is measured directly, so that it does not drown in the noise of
a loaded machine: a timing wrapper just inside it times the env's own ``step``, and
the overhead of a step is the outer time minus the inner time of that same call
(``overhead_ms_per_step``: the median over steps and repeats). The steps that end an
episode, the resets and ``close`` (where recordings are written and flushed) are
measured the same way and reported per episode (``end_of_episode_ms``), and spread
over the steps in ``amortised_overhead_ms_per_step``. ``step_ms`` gives the absolute
median step times for scale. Not counted: the CPU that rerun's background threads
(chunk batching, file writing) take from the env on a machine with few free cores.

With the ``[video]`` extra, ``video`` gives the cost of an episode's video
(:func:`cnt_env.replay.write_video`, 640 x 640): drawing the frames alone, and writing a
GIF and an MP4, per frame.

The bare env runs first: the JSON says whether rerun was imported by then (it must not
be) and whether every wrapped rollout equals the bare one exactly (the wrappers must
not change the env). Episodes that end early (target laid, failure) restart with the
next seed, identically in every variant.

    python benchmarks/replay_overhead.py [--config small|default] [--steps 100]
        [--repeats 3] [--geometry-every 1] [--out FILE.json]

``small`` is the test suite's rod (Hbar 30, 10 physics steps per control step);
``default`` is ``CNTDeposit-v0`` as registered (the paper's serpentine, Hbar 155, with
the env's own simulator settings; the first run computes its warm state, cached).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

CONFIGS: dict[str, dict[str, Any]] = {
    "small": dict(Hbar=30.0, Ibar=200.0, initial_radius=4.0, warmup_length=3.0,
                  control_interval=15.0, reset_advance=2.0, pattern_every=10,
                  sim_options={"dt_factor": 0.05}),
    "default": {},
}  # fmt: skip


class Timed(gymnasium.Wrapper):
    """Times the env's own step/reset/close calls (wrapped just inside the wrapper)."""

    def __init__(self, env: gymnasium.Env) -> None:
        super().__init__(env)
        self.last = 0.0

    def _timed(self, fn: Any, *args: Any, **kwargs: Any) -> Any:
        t = time.perf_counter()
        out = fn(*args, **kwargs)
        self.last = time.perf_counter() - t
        return out

    def step(self, action: Any) -> Any:
        return self._timed(self.env.step, action)

    def reset(self, **kwargs: Any) -> Any:
        return self._timed(self.env.reset, **kwargs)

    def close(self) -> None:
        self._timed(self.env.close)


def rollout(outer: Any, inner: Timed, actions: np.ndarray, seed: int) -> dict[str, Any]:
    """Step ``outer`` through ``actions``; per-step absolute times, per-step overheads
    (outer - inner), the end-of-episode overhead (reset, last step, close), outputs."""
    step_s: list[float] = []
    overhead_s: list[float] = []
    end_s = 0.0
    outputs: list = []
    episodes = 1

    def call(fn: Any, *args: Any, **kwargs: Any) -> tuple[Any, float, float]:
        t = time.perf_counter()
        out = fn(*args, **kwargs)
        dt = time.perf_counter() - t
        return out, dt, dt - inner.last

    _, _, extra = call(outer.reset, seed=seed)
    end_s += extra
    for a in actions:
        (obs, reward, terminated, truncated, _), dt, extra = call(outer.step, a)
        outputs.append((obs.copy(), float(reward)))
        if terminated or truncated:  # the recording is written here
            end_s += extra
            _, _, extra = call(outer.reset, seed=seed + episodes)
            end_s += extra
            episodes += 1
        else:
            step_s.append(dt)
            overhead_s.append(extra)
    _, _, extra = call(outer.close)
    end_s += extra
    return {"step_s": step_s, "overhead_s": overhead_s, "end_s": end_s / episodes,
            "episodes": episodes, "outputs": outputs}  # fmt: skip


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", choices=sorted(CONFIGS), default="small")
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--geometry-every", type=int, default=1)
    parser.add_argument("--out", default=None, help="also write the JSON here")
    args = parser.parse_args(argv)

    import cnt_env  # noqa: F401  (registers CNTDeposit-v0)

    kwargs = dict(CONFIGS[args.config], max_episode_steps=args.steps + 1)
    actions = np.random.default_rng(args.seed).uniform(-1, 1, (args.steps, 2)).astype(np.float32)

    def make() -> Any:
        return gymnasium.make("CNTDeposit-v0", **kwargs)

    # warm-up: numba compile or cache load, the warm state (computed once, cached)
    warm = make()
    warm.reset(seed=args.seed)
    warm.step(actions[0])
    warm.close()

    inner = Timed(make())
    bare = rollout(inner, inner, actions, args.seed)
    rerun_after_bare = "rerun" in sys.modules

    from cnt_env.replay import EpisodeSaver, RerunRecorder

    variants = ("bare", "episode_saver", "rerun_recorder", "rerun_recorder_stream")
    runs: dict[str, list[dict[str, Any]]] = {k: [] for k in variants}
    identical = True
    rrd_bytes = 0
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for variant in variants:
                inner = Timed(make())
                outer: Any = inner
                out_dir = Path(tmp) / f"{variant}{r}"
                if variant == "episode_saver":
                    outer = EpisodeSaver(inner, out_dir, tag="bench")
                elif variant.startswith("rerun_recorder"):
                    outer = RerunRecorder(inner, out_dir, tag="bench",
                                          geometry_every=args.geometry_every,
                                          stream=variant.endswith("stream"))  # fmt: skip
                run = rollout(outer, inner, actions, args.seed)
                runs[variant].append(run)
                identical &= len(run["outputs"]) == len(bare["outputs"]) and all(
                    np.array_equal(o, b) and ro == rb
                    for (o, ro), (b, rb) in zip(run["outputs"], bare["outputs"], strict=True)
                )
                if variant == "rerun_recorder" and r == 0:
                    rrd_bytes = sum(p.stat().st_size for p in out_dir.glob("*.rrd"))
        video = video_cost(sorted((Path(tmp) / "episode_saver0").glob("*.npz"))[0], Path(tmp))

    import rerun

    def median_ms(key: str, variant: str) -> float:
        values = [v for run in runs[variant] for v in run[key]]
        return 1e3 * statistics.median(values)

    step_ms = {k: median_ms("step_s", k) for k in variants}
    overhead = {k: median_ms("overhead_s", k) for k in variants}
    end_ms = {k: 1e3 * statistics.median(run["end_s"] for run in runs[k]) for k in variants}
    per_episode = args.steps / bare["episodes"]
    report = {
        "benchmark": "replay_overhead",
        "config": args.config,
        "env_kwargs": CONFIGS[args.config],
        "steps": args.steps,
        "episodes_per_rollout": bare["episodes"],
        "repeats": args.repeats,
        "geometry_every": args.geometry_every,
        "step_ms": step_ms,
        "overhead_ms_per_step": overhead,
        "overhead_fraction": {k: overhead[k] / step_ms["bare"] for k in variants},
        "end_of_episode_ms": end_ms,
        "amortised_overhead_ms_per_step": {
            k: overhead[k] + (end_ms[k] - end_ms["bare"]) / per_episode for k in variants
        },
        "rrd_bytes_per_step": rrd_bytes / args.steps,
        "video": video,
        "rerun_imported_by_bare_env": rerun_after_bare,
        "wrapped_rollouts_identical_to_bare": bool(identical),
        "rerun_version": rerun.__version__,
        "python": platform.python_version(),
        "machine": platform.machine(),
    }
    text = json.dumps(report, indent=2)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")
    return report


def video_cost(episode_file: Path, tmp: Path, size: tuple[int, int] = (640, 640)) -> Any:
    """Cost of an episode's video (cnt_env.replay.video): drawing the frames alone, and
    writing a GIF and an MP4, in ms per frame; None without the [video] extra."""
    from cnt_env.replay import episode_frames, load_episode, write_video

    try:
        import imageio  # noqa: F401
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        return None
    episode = load_episode(episode_file)
    t0 = time.perf_counter()
    n = sum(1 for _ in episode_frames(episode, size=size))
    draw = time.perf_counter() - t0
    out: dict[str, Any] = {"frames": n, "size": list(size), "draw_ms_per_frame": 1e3 * draw / n}
    for suffix in ("gif", "mp4"):
        t0 = time.perf_counter()
        path = write_video(episode, tmp / f"episode.{suffix}", size=size)
        out[f"{suffix}_ms_per_frame"] = 1e3 * (time.perf_counter() - t0) / n
        out[f"{suffix}_bytes_per_frame"] = path.stat().st_size / n
    return out


if __name__ == "__main__":
    main()
