"""``python -m tests.reference_plant [--fault NAME --size X --fault-start ISO] --seed N --days D out.csv``:
write the independent plant's measurement CSV and print the truth (JSON) on stdout."""

from __future__ import annotations

import argparse
import json

from .csv_output import write_plant_csv
from .faults import FAULTS


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m tests.reference_plant", description=__doc__)
    parser.add_argument("out", help="the CSV to write")
    parser.add_argument("--fault", choices=sorted(FAULTS), default=None)
    parser.add_argument("--size", type=float, default=None, help="the fault's size (default: its clear size)")
    parser.add_argument("--fault-start", default=None, help="ISO date-time the fault starts (default: the start)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--days", type=float, default=7.0)
    parser.add_argument("--start", default="2026-01-15T00:00", help="ISO date-time of the first sample")
    parser.add_argument("--space-column", action="store_true", help="also trend the space around the unit")
    args = parser.parse_args(argv)
    truth = write_plant_csv(args.out, fault=args.fault, size=args.size, fault_start=args.fault_start, seed=args.seed,
                            days=args.days, start=args.start, space_column=args.space_column)
    print(json.dumps(truth.to_dict()))


if __name__ == "__main__":
    main()
