"""Can the agent's observation tell where the planning oracle departs from the route
follower? The classifier AUC of "depart or follow" on held-out label episodes (issue 10).

``cnt-distil`` fits a residual to the oracle's corrections; when its label error barely
beats predicting no correction, either the corrections are not a function of what the
agent observes, or there are too few labels to learn that function. This separates the
two: on the label episodes of a ``cnt-distil`` directory (the fit's split,
``training.distil.held_out``), a logistic regression and a 64x64 tanh MLP, trained with
class weights on the observation (standardised by the training states' statistics),
score each held-out state; the AUC (the probability that a departure outranks a follow)
is reported at fixed epochs (no choice on the held-out states) and as the best of the
epochs checked (chosen on them, so an upper bound), for the first ``--limits`` label
episodes too, as a learning curve in the number of labels. The control step's index
alone is scored as a reference (departures concentrate at the start).

    python benchmarks/label_predictability.py runs/distil_h5c --limits 23,45 \
        --out benchmarks/results/label_predictability_h5c.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

EPOCHS = 200
CHECKED = (10, 50, 200)  # fixed epochs reported
HIDDEN = (0, 64)  # 0: logistic regression


def auc(score: np.ndarray, positive: np.ndarray) -> float:
    """The Mann-Whitney AUC of ``score`` for the boolean ``positive`` (ties broken by
    order; the scores here are continuous)."""
    ranks = np.empty(len(score))
    ranks[np.argsort(score, kind="stable")] = np.arange(1, len(score) + 1)
    p = int(positive.sum())
    n = len(positive) - p
    if p == 0 or n == 0:
        raise ValueError("the AUC needs both departures and follows among the states")
    return float((ranks[positive].sum() - p * (p + 1) / 2) / (p * n))


def arrays(eps: list[dict[str, Any]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Observations, departures (the oracle played another candidate than the
    follower's action) and control-step indices of ``eps``."""
    x = np.concatenate([e["obs"] for e in eps]).astype(np.float32)
    y = np.concatenate([e["chosen"] > 0 for e in eps])
    t = np.concatenate([np.arange(len(e["chosen"])) for e in eps])
    return x, y, t


def classifier_aucs(xt: np.ndarray, yt: np.ndarray, xv: np.ndarray, yv: np.ndarray,
                    hidden: int, seed: int = 0) -> dict[str, float]:  # fmt: skip
    """Held-out AUC at each of ``CHECKED`` epochs, their best, and the training AUC."""
    import torch

    torch.manual_seed(seed)
    d = xt.shape[1]
    if hidden == 0:
        net = torch.nn.Linear(d, 1)
    else:
        net = torch.nn.Sequential(
            torch.nn.Linear(d, hidden), torch.nn.Tanh(),
            torch.nn.Linear(hidden, hidden), torch.nn.Tanh(), torch.nn.Linear(hidden, 1),
        )  # fmt: skip
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, weight_decay=1e-4)
    x, y, x_valid = (torch.as_tensor(a) for a in (xt, yt.astype(np.float32), xv))
    weight = torch.tensor(float((1 - yt.mean()) / yt.mean()))  # balance the classes
    gen = torch.Generator().manual_seed(seed)
    out: dict[str, float] = {}
    for epoch in range(1, EPOCHS + 1):
        for idx in torch.randperm(len(x), generator=gen).split(64):
            loss = torch.nn.functional.binary_cross_entropy_with_logits(
                net(x[idx])[:, 0], y[idx], pos_weight=weight
            )
            opt.zero_grad()
            loss.backward()
            opt.step()
        if epoch % 10 == 0:
            with torch.no_grad():
                a = auc(net(x_valid)[:, 0].numpy(), yv)
            out["best_checked"] = max(out.get("best_checked", 0.0), a)
            if epoch in CHECKED:
                out[f"epoch_{epoch}"] = a
    with torch.no_grad():
        out["train"] = auc(net(x)[:, 0].numpy(), yt)
    return {k: round(v, 3) for k, v in out.items()}


def study(labels: Path, limits: list[int | None]) -> dict[str, Any]:
    import torch

    from training.distil import held_out, load_labels

    torch.set_num_threads(1)
    eps = load_labels(labels)
    valid = [e for e in eps if held_out(e)]
    xv, yv, tv = arrays(valid)
    report: dict[str, Any] = {
        "labels": str(labels), "episodes": len(eps), "valid_states": len(yv),
        "valid_departures": round(float(yv.mean()), 3),
        # earlier steps depart more: the step index, negated, as a score
        "step_index_auc": round(auc(-tv.astype(float), yv), 3), "curve": [],
    }  # fmt: skip
    for limit in limits:
        train = [e for e in eps if not held_out(e)
                 and (limit is None or e["summary"]["index"] < limit)]  # fmt: skip
        xt, yt, _ = arrays(train)
        mu, sd = xt.mean(axis=0), xt.std(axis=0) + 1e-6
        row = {"episodes_below": limit, "train_states": len(yt)}
        for h in HIDDEN:
            row[f"hidden_{h}"] = classifier_aucs((xt - mu) / sd, yt, (xv - mu) / sd, yv, h)
        report["curve"].append(row)
        print(json.dumps(row), flush=True)
    return report


def main(argv: list[str] | None = None) -> int:
    from cnt_env.cli.common import positive_int

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("labels", type=Path, help="a cnt-distil --out directory")
    ap.add_argument("--limits", default="", help="also fit on label episodes of index < N, ...")
    ap.add_argument("--out", type=Path, default=None, help="write the report as JSON")
    args = ap.parse_args(argv)
    limits: list[int | None] = [positive_int(s) for s in args.limits.split(",") if s]
    report = study(args.labels, [*limits, None])
    print(json.dumps({k: v for k, v in report.items() if k != "curve"}))
    if args.out:
        args.out.write_text(json.dumps(report, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
