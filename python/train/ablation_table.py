"""Prints the GRNN ablation table of BENCHMARKS.md from `topoloc suite --json` outputs.

    python3 python/train/ablation_table.py SUITE.json [SUITE.json ...] \
        [--trained-without-temporal SUITE.json ...]

Each file is one suite run (one query condition, any splits); a split measured by several
files (say Train worlds 0-2 in one, Test worlds 6-8 in another) takes each configuration from
the last file that has it. The files after --trained-without-temporal are runs of the `grnn`
configuration with `--grnn-model` naming a network trained with `train.py --no-temporal`:
their `grnn` figures fill that network's row. Prints one Markdown table per condition: a row
per configuration, a column per split, cells "MNA ± std / OHA ± std" over the run's worlds,
and under it the worlds each split was measured on.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

SPLITS = ["train", "tr-t", "tr-a", "test"]
ROWS = [
    ("single-frame", "single-frame"),
    ("filter", "motion filter"),
    ("metric+odometry", "metric mode (+ odometry)"),
    ("grnn-no-temporal", "GRNN, state zeroed every frame"),
    ("grnn-trained-no-temporal", "GRNN trained without temporal module"),
    ("grnn", "**GRNN**"),
    ("grnn+gc", "GRNN + GC"),
    ("grnn+s-gc", "GRNN + s-GC"),
]


def cell(figures: dict[str, Any]) -> str:
    """`MNA ± std / OHA ± std` of one configuration on one split."""
    return (
        f"{figures['mna_mean']:.3f} ± {figures['mna_std']:.3f} / "
        f"{figures['oha_mean']:.3f} ± {figures['oha_std']:.3f}"
    )


def collect(
    paths: list[Path], without_temporal: list[Path]
) -> dict[str, dict[str, dict[str, Any]]]:
    """condition -> split -> {"configurations": {name: figures}, "worlds": {name: "K-L"}}."""
    tables: dict[str, dict[str, dict[str, Any]]] = {}
    runs = [(p, False) for p in paths] + [(p, True) for p in without_temporal]
    for path, trained_without_temporal in runs:
        run = json.loads(path.read_text())
        splits = tables.setdefault(run["condition"], {})
        for split, measured in run["splits"].items():
            entry = splits.setdefault(split, {"configurations": {}, "worlds": {}})
            worlds = [w["world"] for w in measured["worlds"]]
            for name, figures in measured["configurations"].items():
                if trained_without_temporal:
                    if name != "grnn":
                        continue
                    name = "grnn-trained-no-temporal"
                entry["configurations"][name] = figures
                entry["worlds"][name] = f"{worlds[0]}-{worlds[-1]}"
    return tables


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="topoloc suite --json outputs")
    parser.add_argument(
        "--trained-without-temporal",
        nargs="+",
        type=Path,
        default=[],
        help="suite runs of a network trained with train.py --no-temporal (its grnn rows)",
    )
    args = parser.parse_args()
    tables = collect(args.runs, args.trained_without_temporal)
    for condition, splits in sorted(tables.items()):
        present = [s for s in SPLITS if s in splits]
        print(f"\n{condition} query light; MNA ± std / OHA ± std\n")
        print("| configuration | " + " | ".join(present) + " |")
        print("|---|" + "---|" * len(present))
        for name, label in ROWS:
            cells = [
                cell(splits[s]["configurations"][name])
                if name in splits[s]["configurations"]
                else "—"
                for s in present
            ]
            print(f"| {label} | " + " | ".join(cells) + " |")
        for s in present:
            worlds = sorted(set(splits[s]["worlds"].values()))
            print(f"\n{s}: worlds {', '.join(worlds)}", end="")
        print()


if __name__ == "__main__":
    main()
