"""Do two versions of mountcal choose the same models? Compare two ``effects.py --choices`` files.

    git worktree add /tmp/mountcal-old OLD_COMMIT
    PYTHONPATH=/tmp/mountcal-old/src python benchmarks/effects.py --runs 100 --choices old.json
    PYTHONPATH=src python benchmarks/effects.py --runs 100 --choices new.json
    python benchmarks/compare_choices.py old.json new.json

A run agrees when the whole path is the same: every step added, in order, with the same stops
excluded. Prints each disagreement, the agreement per scenario and overall, and (where the files
carry them) the largest change of an angle.
"""

from __future__ import annotations

import argparse
import json


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("old")
    ap.add_argument("new")
    args = ap.parse_args()
    with open(args.old, encoding="utf-8") as fh:
        old = json.load(fh)
    with open(args.new, encoding="utf-8") as fh:
        new = json.load(fh)
    total = same = 0
    for scenario, runs in old.items():
        other = new.get(scenario, [])
        if len(other) != len(runs):
            raise SystemExit(f"{scenario}: {len(runs)} runs in {args.old}, {len(other)} in {args.new}")
        agree, moved = 0, 0.0
        for i, (a, b) in enumerate(zip(runs, other, strict=True)):
            if (a["model"], a["steps"]) == (b["model"], b["steps"]):
                agree += 1
                if "angles_deg" in a:
                    both = [(x, y) for x, y in zip(a["angles_deg"], b["angles_deg"], strict=True) if None not in (x, y)]
                    moved = max([moved] + [abs(x - y) for x, y in both])
            else:
                print(f"{scenario}, run {i}: {a['steps']} → {b['steps']}")
        print(f"{scenario}: {agree}/{len(runs)}" + (f", angles within {moved:.2g}°" if "angles_deg" in runs[0] else ""))
        total, same = total + len(runs), same + agree
    print(f"all: {same}/{total} runs choose the same path ({same / max(total, 1):.2%})")


if __name__ == "__main__":
    main()
