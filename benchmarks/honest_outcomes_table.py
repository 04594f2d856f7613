"""results/robots/honest_outcomes_2026-11-25/README.md's tables from <run>/height_sweep.csv there, beside the reported
sweep's results/robots/quadruped_step_2026-11-25/<run>_sweep/height_sweep.csv (its success_rate was 'beyond the line at
the end'). (Moved from that folder in round 6, issue 76: results/ holds records, not code.)

    python benchmarks/honest_outcomes_table.py ft_q10r ft_q8r ft_q9 ...
"""
import csv
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[1] / "results" / "robots" / "honest_outcomes_2026-11-25"
OLD = HERE.parent / "quadruped_step_2026-11-25"


def rows(path: Path) -> dict:
    return {float(r["step_height_m"]): r for r in csv.DictReader(open(path))}


def pct(x) -> str:
    return f"{float(x):.0%}"


print("| run | height | success (crossed, not terminated) | beyond the line at the end (reported before) "
      "| terminated: by reason | stride (Hz) | per foot on the ground LF / RF / LH / RH | touchdowns/s LF / RF / LH / RH "
      "| pairs down together: diagonal / same side / same end |")
print("|---|---|---|---|---|---|---|---|---|")
for run in sys.argv[1:]:
    new, old = rows(HERE / run / "height_sweep.csv"), rows(OLD / f"{run}_sweep" / "height_sweep.csv")
    for height, r in new.items():
        reasons = ", ".join(f"{k[len('terminated: '):]} {pct(v)}" for k, v in r.items()
                            if k.startswith("terminated: ") and float(v) > 0)
        feet = [k[len("foot_contact_share "):] for k in r if k.startswith("foot_contact_share ")]
        share = " / ".join(f"{float(r['foot_contact_share ' + f]):.2f}" for f in feet)
        touch = " / ".join(f"{float(r['touchdown_frequency ' + f]):.1f}" for f in feet)
        pairs = " / ".join(f"{float(r[k]):.2f}" if r[k] else "-" for k in
                           ("diagonal_pairs_together", "same_side_pairs_together", "same_end_pairs_together"))
        before = pct(old[height]["success_rate"]) if height in old else "-"
        print(f"| {run} | {height * 100:g} cm | **{pct(r['success_rate'])}** | {pct(r['crossed_at_end_rate'])} ({before}) "
              f"| {pct(r['terminated_share'])}{': ' + reasons if reasons else ''} | {float(r['stride_frequency']):.1f} "
              f"| {share} | {touch} | {pairs} |")
