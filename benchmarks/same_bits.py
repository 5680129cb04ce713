"""Do two ``cnt-evaluate`` result directories hold the same episodes, to every bit?

The check of a machine's determinism across CPUs (docs/architecture.md, "Determinism"):
lay the committed held-out table again and compare it with the committed one::

    cnt-evaluate --policies random,constant,scripted,ppo_residual,ppo,sac --seeds 0,1,2 \\
        --jobs 2 --out OUT
    python benchmarks/same_bits.py OUT training/results

Every episode of ``OUT`` is looked up in the reference by (policy, target, seed) and
compared in every field of ``episodes.json`` but ``wall_s`` (its floats are written to
round-trip, so equal means the same float64 bits; ``episodes.csv`` prints 6 digits), and
by its trace and target in ``traces.npz`` (array equality of the stored float32).
Prints, per policy, how many episodes are equal, then each that is not with its
differing fields; exits 1 if any differs or is missing from the reference. Episodes of
the reference that ``OUT`` did not lay are not counted (``OUT`` may be a subset: fewer
policies, targets or seeds).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

#: Columns that are allowed to differ: the wall time of an episode.
IGNORED = ("wall_s",)


def episodes(path: Path) -> tuple[list[dict[str, Any]], dict[str, np.ndarray]]:
    """``path/episodes.json``'s rows, and ``traces.npz``'s arrays ({} if absent)."""
    rows = json.loads((path / "episodes.json").read_text())
    npz = path / "traces.npz"
    if not npz.is_file():
        return rows, {}
    with np.load(npz) as data:
        return rows, {k: data[k] for k in data.files}


def differences(new: Path, ref: Path) -> tuple[Counter, Counter, list[str]]:
    """Per policy the episodes of ``new`` and those equal to ``ref``'s, and a line for
    each episode that differs (its key and what differs)."""
    rows, arrays = episodes(new)
    ref_rows, ref_arrays = episodes(ref)
    where = {(r["policy"], r["target"], r["seed"]): i for i, r in enumerate(ref_rows)}
    total, equal, lines = Counter(), Counter(), []
    for i, row in enumerate(rows):
        key = (row["policy"], row["target"], row["seed"])
        name = f"{key[0]} {key[1]} seed {key[2]}"
        total[key[0]] += 1
        j = where.get(key)
        if j is None:
            lines.append(f"{name}: not in {ref}")
            continue
        other = ref_rows[j]
        what = [c for c in sorted(set(row) | set(other))
                if c not in IGNORED and row.get(c) != other.get(c)]  # fmt: skip
        what += [f"{name}_ (traces.npz)" for name in ("trace", "target")
                 if f"{name}_{i}" in arrays and not np.array_equal(
                     arrays[f"{name}_{i}"], ref_arrays.get(f"{name}_{j}"))]  # fmt: skip
        if what:
            lines.append(f"{name}: {', '.join(what)} (score {row.get('score')} "
                         f"against {other.get('score')})")  # fmt: skip
        else:
            equal[key[0]] += 1
    return total, equal, lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("new", type=Path, help="a cnt-evaluate --out directory")
    p.add_argument("reference", type=Path, help="the directory to compare with "
                   "(e.g. training/results)")  # fmt: skip
    args = p.parse_args(argv)
    for d in (args.new, args.reference):
        if not (d / "episodes.json").is_file():
            p.error(f"{d} has no episodes.json: pass a cnt-evaluate --out directory")
    total, equal, lines = differences(args.new, args.reference)
    for policy, n in total.items():
        print(f"{policy:<16} {equal[policy]:>4} of {n:>4} episodes equal")
    for line in lines:
        print(line)
    same = not lines and sum(total.values()) > 0
    print("the same bits" if same else f"{len(lines)} episodes differ or are missing")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
