#!/usr/bin/env python3
"""How far training got against what the policy then did: for every evaluated run given, the mean
training action loss over its last 250 steps (metrics.jsonl), its last validation action loss
(val.jsonl) and the first task row of eval/results.json (subgoal completion and success, %);
then the runs grouped by that training loss.

    python3 scripts/loss_vs_success.py runs/lg_task_* runs/lgp_*

Runs without metrics or evaluation are skipped (named on stderr). Standard library only.
"""
import json
import statistics
import sys
from pathlib import Path

BUCKETS = [(0.0, 0.05), (0.05, 0.08), (0.08, float("inf"))]


def row(run: Path):
    """(train loss, val loss, completion, success) of an evaluated run, or None."""
    try:
        steps = [json.loads(l) for l in (run / "metrics.jsonl").read_text().splitlines() if l]
        val = [json.loads(l) for l in (run / "val.jsonl").read_text().splitlines() if l]
        res = json.loads((run / "eval" / "results.json").read_text())
    except (OSError, ValueError):
        return None
    if not steps:
        return None
    last = steps[-1]["step"]
    train = statistics.mean(s["action"] for s in steps if s["step"] > last - 250)
    task = res["tasks"][0] if isinstance(res.get("tasks"), list) and res["tasks"] else None
    if task is None or "completion" not in task or "success" not in task:
        return None
    v = val[-1]["action"] if val else float("nan")
    return train, v, float(task["completion"]), float(task["success"])


def main(args):
    if not args:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    rows = []
    for a in args:
        p = Path(a)
        if not p.is_dir():
            continue
        r = row(p)
        if r is None:
            print(f"skipped {p}: no metrics or no evaluation", file=sys.stderr)
            continue
        rows.append((*r, p.name))
    if not rows:
        print("error: no evaluated run among the arguments", file=sys.stderr)
        return 2
    rows.sort()
    print("| run | train action loss (last 250 steps) | val action loss | completion % | success % |")
    print("|---|---:|---:|---:|---:|")
    for t, v, c, s, n in rows:
        print(f"| {n} | {t:.3f} | {v:.3f} | {c:.1f} | {s:.1f} |")
    print()
    print("| train action loss | runs | completion ≥ 50 % | mean completion % | mean success % |")
    print("|---|---:|---:|---:|---:|")
    for lo, hi in BUCKETS:
        b = [r for r in rows if lo <= r[0] < hi]
        if not b:
            continue
        name = f"≥ {lo:.2f}" if hi == float("inf") else f"{lo:.2f}–{hi:.2f}"
        print(
            f"| {name} | {len(b)} | {sum(r[2] >= 50 for r in b)} "
            f"| {statistics.mean(r[2] for r in b):.1f} | {statistics.mean(r[3] for r in b):.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
