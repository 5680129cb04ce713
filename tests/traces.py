"""Synthetic traces with known answers, shared by the pattern and CLI tests: coils,
U-shaped serpentines (optionally with loops) and random walks, in the substrate plane."""

from __future__ import annotations

import numpy as np

from cnt_env.patterns import arc_length

R0_BAR = 7.64  # the paper's coil radius (docs/model.md §6)
A_BAR, LAMBDA_BAR = 30.0, 7.0  # the paper's serpentine amplitude and wavelength


def resample(curve: np.ndarray, spacing: float) -> np.ndarray:
    """Points every ``spacing`` of arc length along a dense polyline."""
    s = arc_length(curve)
    t = np.arange(0.0, s[-1], spacing)
    return np.stack([np.interp(t, s, curve[:, 0]), np.interp(t, s, curve[:, 1])], axis=1)


def coil_trace(
    length: float,
    radius: float = R0_BAR,
    spacing: float = 0.5,
    drift_per_turn: tuple[float, float] = (0.4, 0.15),
    noise: float = 0.01,
    seed: int = 0,
) -> np.ndarray:
    """Planar coil: a circle of ``radius`` whose centre drifts slowly, plus noise."""
    phase = np.arange(0.0, length / radius, spacing / radius)
    drift = np.outer(phase / (2 * np.pi), drift_per_turn)
    pts = drift + radius * np.stack([np.cos(phase), np.sin(phase)], axis=1)
    return pts + noise * np.random.default_rng(seed).standard_normal(pts.shape)


def serpentine_curve(
    runs: list[float],
    wavelength: float,
    spacing: float,
    loop_every: int = 0,
    loop_radius: float = 3.0,
) -> np.ndarray:
    """U-shaped serpentine advancing along +x, steps along z, sampled every ``spacing``.

    Run k goes along z (up for even k) from z = 0 to z = runs[k] ... and is joined
    to the next by a semicircle of diameter wavelength / 2 beyond the run's end,
    so same-side U-turns are one wavelength apart in x and the extremes of z are
    wavelength / 4 beyond the runs. With ``loop_every`` = k, every k-th up-run
    gets a full loop (a prolate trochoid, which crosses itself) half-way up.
    """
    r_turn = wavelength / 4
    dense = 0.02
    pieces: list[np.ndarray] = []
    x = 0.0
    for k, run in enumerate(runs):
        up = k % 2 == 0
        z0, z1 = (0.0, run) if up else (run, 0.0)
        if up and loop_every and (k // 2) % loop_every == loop_every - 1:
            # z = zm + a t + r sin t, x = x + r (cos t - 1): heading +z at both ends
            a = 0.5 * loop_radius
            zm = 0.5 * (run - 2 * np.pi * a)
            t = np.arange(0.0, 2 * np.pi, dense / loop_radius)
            pieces.append(np.stack([np.full(2, x), [z0, zm]], axis=1))
            pieces.append(
                np.stack(
                    [x + loop_radius * (np.cos(t) - 1), zm + a * t + loop_radius * np.sin(t)], 1
                )
            )
            pieces.append(np.stack([np.full(2, x), [zm + 2 * np.pi * a, z1]], axis=1))
        else:
            pieces.append(np.stack([np.full(2, x), [z0, z1]], axis=1))
        if k == len(runs) - 1:
            break
        t = np.arange(0.0, np.pi, dense / r_turn)
        if up:  # over the top: angle pi -> 0
            arc = np.stack([x + r_turn + r_turn * np.cos(np.pi - t), z1 + r_turn * np.sin(t)], 1)
        else:  # under the bottom: angle pi -> 2 pi
            arc = np.stack([x + r_turn + r_turn * np.cos(np.pi + t), -r_turn * np.sin(t)], 1)
        pieces.append(arc)
        x += 2 * r_turn
    curve = np.concatenate(pieces)
    return resample(curve, spacing)


def serpentine_trace(
    n_runs: int = 44,
    run: float = 2 * A_BAR - LAMBDA_BAR / 2,
    wavelength: float = LAMBDA_BAR,
    spacing: float = 0.5,
    noise: float = 0.01,
    seed: int = 0,
    **kwargs: float,
) -> np.ndarray:
    curve = serpentine_curve([run] * n_runs, wavelength, spacing, **kwargs)  # type: ignore[arg-type]
    return curve + noise * np.random.default_rng(seed).standard_normal(curve.shape)


def random_walk(n: int, step: float = 0.5, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.cumsum(step * rng.standard_normal((n, 2)), axis=0)
