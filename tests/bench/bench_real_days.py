"""graphtwin's diagnosis on every day of the LBNL FLEXLAB X3A data (SZVAV, September 2017): the seven
days with one imposed fault each and the four unfaulted days, all with one fixed protocol.

Protocol (no per-day tuning): 15-minute block means of the 1-minute log (``graphtwin data
block-means``); the base model ``flexlab_ahu`` calibrated on the unfaulted day nearest in date that is not the test day (ties: the earlier day); the test window is the
whole test day; ``diagnose`` at its defaults, ``seed=0``, ``workers=1``; the days run in a process pool
of 2. "Right component" is fixed per fault before the run (:data:`RIGHT_COMPONENTS`): heating-coil
valve faults → ``heating_coil_valve`` or ``heating_coil``, cooling-coil valve faults → ``cooling_coil``
or ``cooling_coil_valve``, outdoor air damper faults → ``outdoor_air_damper`` or ``mixing_box``. On an
unfaulted day any significant effect is a false alarm. Results and their reading: ``docs/real-days.md``.

    python tests/bench/bench_real_days.py [--days 2017-09-12 2017-09-20] [--json-dir DIR]
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import sys
import tempfile
import time
import warnings
from concurrent.futures import ProcessPoolExecutor, as_completed
from datetime import date
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run as a script: tests/ holds shared_data

from shared_data import SZVAV  # noqa: E402

from service.data.block_means import write_block_means  # noqa: E402
from service.diagnosis.loop import diagnose  # noqa: E402
from service.errors import GraphtwinError  # noqa: E402
from service.graph.namespaces import local_name  # noqa: E402
from service.graph.store import GraphStore  # noqa: E402
from service.resources import examples_dir  # noqa: E402

EX = "https://example.org/flexlab-x3a#"
SUPPLY = EX + "supply_air_temperature_sensor"
AVERAGE_MINUTES = 15
HEATING = frozenset({"heating_coil_valve", "heating_coil"})
COOLING = frozenset({"cooling_coil_valve", "cooling_coil"})
OUTDOOR_DAMPER = frozenset({"outdoor_air_damper", "mixing_box"})
#: day → (the fault logged for it in ../shared/realdata/README.md, the components that count as right)
FAULTS: dict[str, tuple[str, frozenset[str]]] = {
    "2017-09-11": ("cooling-coil valve leak 50 %", COOLING),
    "2017-09-12": ("heating-coil valve leak 40 %", HEATING),
    "2017-09-14": ("heating-coil valve stuck 100 %", HEATING),
    "2017-09-15": ("heating-coil valve stuck 50 %", HEATING),
    "2017-09-18": ("OA damper stuck at minimum", OUTDOOR_DAMPER),
    "2017-09-19": ("OA damper stuck 100 %", OUTDOOR_DAMPER),
    "2017-09-22": ("cooling-coil valve stuck 100 %", COOLING),
}
UNFAULTED = ("2017-09-20", "2017-09-21", "2017-09-23", "2017-09-24")
RIGHT_COMPONENTS = {day: right for day, (_, right) in FAULTS.items()}


#: The unfaulted days that follow one another: the two-day training stretches.
UNFAULTED_PAIRS = (("2017-09-20", "2017-09-21"), ("2017-09-23", "2017-09-24"))


def training_day(day: str) -> str:
    """The unfaulted day nearest in date to ``day`` that is not ``day`` (ties: the earlier)."""
    test = date.fromisoformat(day)
    return min((d for d in UNFAULTED if d != day), key=lambda d: (abs((date.fromisoformat(d) - test).days), d))


def training_days(day: str, count: int) -> tuple[str, str]:
    """The first and last day of the training window: :func:`training_day` for one day; for two, the
    pair of consecutive unfaulted days without ``day`` whose nearer day is nearest to it (ties: the
    earlier pair)."""
    if count == 1:
        return (training_day(day),) * 2
    test = date.fromisoformat(day)
    pairs = [p for p in UNFAULTED_PAIRS if day not in p]
    return min(pairs, key=lambda p: (min(abs((date.fromisoformat(d) - test).days) for d in p), p))


def last_block(data: Path, day: str) -> str:
    """The start of ``day``'s last block in the averaged file (9/24 lacks a minute, so its last whole
    block starts at 23:30): the end of a window that is the whole day."""
    with data.open(newline="", encoding="utf-8") as handle:
        return [row[0] for row in csv.reader(handle) if row[0].startswith(day)][-1]


MODEL = examples_dir() / "flexlab_ahu" / "model.ttl"


def diagnose_day(day: str, folder: str, model: Path = MODEL, training_count: int = 1) -> dict:
    """One day under the protocol, the building model ``model``, trained on ``training_count``
    unfaulted days (:func:`training_days`): the report's JSON (``to_dict``) and the table's facts."""
    first, last = training_days(day, training_count)
    train = first if first == last else f"{first}/{last[5:]}"
    data = Path(folder) / f"szvav_{AVERAGE_MINUTES}min_{day}.csv"
    write_block_means(SZVAV, data, AVERAGE_MINUTES, {first, last, day})
    store = GraphStore.embedded(None)
    store.load_model("flexlab", model)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unclaimed columns (set points, status, occupancy)
        report = diagnose(store, "flexlab", data, train=(first, last_block(data, last)),
                          test=(day, last_block(data, day)), seed=0, workers=1)
    seconds = time.perf_counter() - start
    top = report.effects[0] if report.effects else None
    return {
        "day": day, "train": train, "seconds": seconds,
        "top": f"{top.effect} @ {local_name(top.node)}" if top else "—",
        "top_node": local_name(top.node) if top else None,
        "top_significant": bool(top and top.significant),
        "supply_removed": top.error_removed_at(SUPPLY) if top else float("nan"),
        "supply_fails": report.sensors[SUPPLY].fails,
        "answer": f"{report.answer.effect} @ {local_name(report.answer.node)}" if report.answer else None,
        "indistinguishable": [f"{t.effect.effect} @ {local_name(t.effect.node)}" for t in report.indistinguishable],
        "report": json.loads(json.dumps(report.to_dict(), default=float)),
    }


def table(rows: list[dict]) -> str:
    """The markdown table of the finished days, in date order, with the counts below it."""
    lines = ["| day | logged fault | trained on | top effect @ node | significant | right first "
             "| supply-air error removed | answer | indistinguishable | false alarm |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for row in sorted(rows, key=lambda r: r["day"]):
        fault, right = FAULTS.get(row["day"], ("none (unfaulted)", frozenset()))
        faulted = row["day"] in FAULTS
        right_first = ("yes" if row["top_node"] in right else "no") if faulted else "—"
        alarm = "—" if faulted else ("yes" if row["answer"] else "no")
        lines.append(f"| {row['day'][5:]} | {fault} | {row['train'][5:]} | {row['top']} "
                     f"| {'yes' if row['top_significant'] else 'no'} | {right_first} "
                     f"| {row['supply_removed']:.0%} | {row['answer'] or 'none'} "
                     f"| {'; '.join(row['indistinguishable']) or '—'} | {alarm} |")
    faulted = [r for r in rows if r["day"] in FAULTS]
    unfaulted = [r for r in rows if r["day"] not in FAULTS]
    right = sum(r["top_node"] in RIGHT_COMPONENTS[r["day"]] for r in faulted)
    right_answer = sum(r["answer"] is not None and r["top_node"] in RIGHT_COMPONENTS[r["day"]] for r in faulted)
    lines += ["", f"Faulted days: right component first {right}/{len(faulted)}, and significant (the answer) "
              f"{right_answer}/{len(faulted)}; some significant answer {sum(bool(r['answer']) for r in faulted)}"
              f"/{len(faulted)}. Unfaulted days: false alarms {sum(bool(r['answer']) for r in unfaulted)}"
              f"/{len(unfaulted)}."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--days", nargs="+", default=sorted([*FAULTS, *UNFAULTED]), help="ISO dates (default: all 11)")
    parser.add_argument("--training-days", type=int, choices=(1, 2), default=1,
                        help="train on the nearest unfaulted day (1, the protocol) or two consecutive ones (2)")
    parser.add_argument("--json-dir", type=Path, help="write each day's report.to_dict() as DAY.json here")
    parser.add_argument("--model", type=Path, default=MODEL,
                        help="the building model (default: the FLEXLAB example; e.g. one an effect was added to)")
    args = parser.parse_args()
    if not SZVAV.is_file():
        sys.exit(f"skipped: {SZVAV} is absent (the FLEXLAB data live in ../shared/realdata)")
    unknown = set(args.days) - set(FAULTS) - set(UNFAULTED)
    if unknown:
        parser.error(f"not a FLEXLAB day: {sorted(unknown)}")
    if args.json_dir:
        args.json_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as folder, ProcessPoolExecutor(max_workers=2) as pool:
        futures = {pool.submit(diagnose_day, day, folder, args.model, args.training_days): day for day in args.days}
        for future in as_completed(futures):
            try:
                row = future.result()
            except GraphtwinError as error:
                print(f"{futures[future]}: not diagnosed: {error}", flush=True)
                continue
            rows.append(row)
            print(f"{row['day']}: {row['top']} (significant: {row['top_significant']}), answer {row['answer']}, "
                  f"{row['seconds']:.0f} s", flush=True)
            if args.json_dir:
                (args.json_dir / f"{row['day']}.json").write_text(json.dumps(row["report"], indent=1))
    print(table(rows))


if __name__ == "__main__":
    main()
