"""Soak: many short CNTDeposit-v0 episodes in one process, RSS sampled, memory must stay flat.

    python benchmarks/soak.py --episodes 1000 --steps 4

Each episode resets with a new seed (so a new target is drawn) and takes ``--steps``
random actions. The resident set size (RSS) is sampled after every ``--every`` episodes.
The figure of merit is the growth of RSS from the end of the warm-up (the first
``--warmup`` episodes: numba compilation, the warm-start cache, first allocations) to
the end, as a percentage. Writes ``benchmarks/results/soak.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import cnt_env  # noqa: F401  (registers CNTDeposit-v0)

RESULTS = Path(__file__).resolve().parent / "results" / "soak.json"


def rss_mib() -> float:
    """Resident set size of this process (Linux /proc; MiB)."""
    with open(f"/proc/{os.getpid()}/statm") as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=1000)
    ap.add_argument("--steps", type=int, default=4, help="random actions per episode")
    ap.add_argument("--warmup", type=int, default=50, help="episodes before the baseline RSS")
    ap.add_argument("--every", type=int, default=25, help="sample RSS every N episodes")
    ap.add_argument("--preset", default="serpentine")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    if args.episodes <= args.warmup:
        ap.error("--episodes must exceed --warmup")

    env = gym.make("CNTDeposit-v0", preset=args.preset)
    rng = np.random.default_rng(0)
    samples: list[tuple[int, float]] = []
    failures = 0
    t0 = time.perf_counter()
    for ep in range(args.episodes):
        env.reset(seed=ep)
        for _ in range(args.steps):
            _, _, terminated, truncated, info = env.step(rng.uniform(-1, 1, 2).astype(np.float32))
            failures += "failure" in info
            if terminated or truncated:
                break
        if (ep + 1) % args.every == 0 or ep + 1 == args.warmup:
            samples.append((ep + 1, rss_mib()))
            print(f"episode {ep + 1:5d}  RSS {samples[-1][1]:8.1f} MiB", flush=True)
    env.close()
    wall = time.perf_counter() - t0
    base = next(r for e, r in samples if e >= args.warmup)
    end = samples[-1][1]
    after = [r for e, r in samples if e >= args.warmup]
    result = {
        "command": "python benchmarks/soak.py " + " ".join(sys.argv[1:] if argv is None else argv),
        "episodes": args.episodes,
        "steps_per_episode": args.steps,
        "preset": args.preset,
        "wall_s": round(wall, 1),
        "failures": failures,
        "rss_after_warmup_mib": round(base, 1),
        "rss_end_mib": round(end, 1),
        "rss_max_after_warmup_mib": round(max(after), 1),
        "growth_percent": round(100.0 * (end - base) / base, 2),
        "samples": [[e, round(r, 1)] for e, r in samples],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(
        f"{args.episodes} episodes in {wall:.0f} s: RSS {base:.1f} -> {end:.1f} MiB "
        f"({result['growth_percent']:+.2f}%), max {max(after):.1f} MiB; failures {failures}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
