"""The rule-based peer on the same FLEXLAB X3A days as ``bench_real_days.py``: open-fdd's cookbook rules
(``open_fdd.rules.run_all``, the ``bench`` extra: ``pip install -e ".[bench]"``) at their defaults.

Protocol: the 1-minute log of each whole day (no averaging: the rules confirm a fault over minutes,
``poll_seconds=60``), °F and 0–1 commands as logged, the columns renamed to open-fdd's roles
(:data:`COLUMN_ROLES`), the frame stamped ``equipment_type="AHU"``, no web weather. A rule "fires" when
its status is ``FAULT``; the component a rule points at is read from its title
(:data:`RULE_COMPONENTS`, fixed before the run; sensor, schedule, set point and control rules point at
none). Results and their reading: ``docs/real-days.md``.

    python tests/bench/bench_peer_openfdd.py [--days 2017-09-12 2017-09-20]
"""

from __future__ import annotations

import argparse
import sys

import pandas as pd
from bench_real_days import COOLING, FAULTS, HEATING, OUTDOOR_DAMPER, SZVAV, UNFAULTED

#: SZVAV.csv header (stripped) → open-fdd role. No role: the SAT heating set point (``heating-sp`` and
#: ``cooling-sp`` are zone set points of the FCU rules), the return and exhaust damper commands
#: (``damper-cmd`` is an FCU's), the ground-truth column.
COLUMN_ROLES = {
    "AHU: Supply Air Temperature": "discharge-air-temp",
    "AHU: Supply Air Temperature Cooling Set Point": "discharge-air-temp-sp",
    "AHU: Outdoor Air Temperature": "outside-air-temp",
    "AHU: Mixed Air Temperature": "mixed-air-temp",
    "AHU: Return Air Temperature": "return-air-temp",
    "AHU: Supply Air Fan Status": "fan-status",
    "AHU: Supply Air Fan Speed Control Signal": "fan-cmd",
    "AHU: Outdoor Air Damper Control Signal": "outside-air-damper",
    "AHU: Cooling Coil Valve Control Signal": "cooling-valve",
    "AHU: Heating Coil Valve Control Signal": "heating-valve",
    "Occupancy Mode Indicator": "occupied",
}
HEATING_COIL, COOLING_COIL, OA_DAMPER = "heating coil", "cooling coil", "OA damper"
#: rule → the components its title names (GL36 FC8, SAT ≠ MAT + fan heat with the coils idle, and
#: simultaneous heating and cooling name both coils)
RULE_COMPONENTS = {
    **dict.fromkeys(["FC5", "FC7", "FC15", "ECON-5", "FCU-HTG-COIL", "FCU-VALVE-PASS-HTG"], {HEATING_COIL}),
    **dict.fromkeys(["FC12", "FC13", "FC14", "VLV-1", "FCU-CLG-COIL", "FCU-VALVE-PASS-CLG"], {COOLING_COIL}),
    **dict.fromkeys(["FC8", "AHU-SIMUL"], {HEATING_COIL, COOLING_COIL}),
    **dict.fromkeys(["FC6", "FC9", "FC10", "FC11", "ECON-1", "ECON-2", "ECON-3", "ECON-4", "ECON-6", "ECON-7",
                     "DMP-1", "OA-1"], {OA_DAMPER}),
}
FAULTED_COMPONENT = {HEATING: HEATING_COIL, COOLING: COOLING_COIL, OUTDOOR_DAMPER: OA_DAMPER}
#: what the fired rules' metrics hold besides a fault's hours and share: gates, data quality, weather
#: source, runtime and evidence bookkeeping (none is a size of the fault: a leak's flow, a stuck position)
BOOKKEEPING = {"gate_kind", "gate_applied", "gate_source", "active_sample_count", "active_coverage_pct",
               "startup_delay_seconds", "weather_source", "has_web_weather", "has_bas_oat", "oa_t_source",
               "quality", "quality_confidence", "sensors_checked", "total_sample_count", "proof_source",
               "proof_confidence", "conflicting_signal_hours", "inferred_runtime_hours", "proven_runtime_hours",
               "sv_rate_evidence", "sv_rate_state_meta", "sv_sweep_confirmed_roles", "sv_sweep_evidence"}


def role_frame(source=SZVAV) -> pd.DataFrame:
    """The whole log as a role-named frame on its timestamps (spreadsheet error cells → NaN)."""
    raw = pd.read_csv(source)
    raw.columns = [c.strip() for c in raw.columns]
    frame = raw[list(COLUMN_ROLES)].rename(columns=COLUMN_ROLES).apply(pd.to_numeric, errors="coerce")
    frame.index = pd.to_datetime(raw["Datetime"], format="%m/%d/%Y %H:%M")
    return frame


def check_mapping() -> None:
    """Every role and rule this bench names is one of the installed open-fdd's (a renamed role would
    otherwise leave a rule silently skipped)."""
    from open_fdd import rules

    roles = {role for rule in rules.RULES for role in [*rule.required_roles, *rule.optional_roles]}
    unknown = sorted(set(COLUMN_ROLES.values()) - roles) + sorted(set(RULE_COMPONENTS) - set(rules.RULES_BY_ID))
    if unknown:
        raise SystemExit(f"open-fdd knows no role or rule {', '.join(unknown)}: update COLUMN_ROLES / RULE_COMPONENTS")


def run_day(frame: pd.DataFrame, day: str) -> dict:
    """open-fdd's rules at their defaults on one day: the fired rules and what they name."""
    from open_fdd.rules import run_all

    one = frame.loc[day].copy()
    one.attrs.update(equipment_id="AHU-X3A", equipment_type="AHU")
    results = run_all(one, poll_seconds=60.0)
    fired = [r for r in results if r.status == "FAULT"]
    return {
        "day": day,
        "fired": {r.rule_id: r.fault_pct for r in fired},
        "components": {r.rule_id: RULE_COMPONENTS.get(r.rule_id, set()) for r in fired},
        "size_metrics": sorted({k for r in fired for k in (r.metrics or {})} - BOOKKEEPING),
        "missing_roles": sorted({role for r in results if r.status == "SKIPPED_MISSING_ROLES"
                                 for role in r.missing_roles}),
    }


def table(rows: list[dict]) -> str:
    """The markdown table, in date order, with the counts below it. "Beyond the unfaulted days": the
    fired rules whose share exceeds their largest share on the unfaulted days of the run."""
    unfaulted_max: dict[str, float] = {}
    for row in rows:
        if row["day"] not in FAULTS:
            for rule, share in row["fired"].items():
                unfaulted_max[rule] = max(share, unfaulted_max.get(rule, 0.0))
    lines = ["| day | logged fault | rules fired (share of the active day) | naming the faulted component "
             "| beyond the unfaulted days | sizes the fault |", "|---|---|---|---|---|---|"]
    named, named_beyond, alarms = 0, 0, 0
    for row in sorted(rows, key=lambda r: r["day"]):
        fault, right = FAULTS.get(row["day"], ("none (unfaulted)", None))
        fired = ", ".join(f"{rule} {share:.0f} %" for rule, share in row["fired"].items()) or "none"
        beyond = [rule for rule, share in row["fired"].items() if share > unfaulted_max.get(rule, 0.0)]
        if right is None:
            naming, beyond_text = "—", "—"
            alarms += bool(row["fired"])
        else:
            hits = [rule for rule, names in row["components"].items() if FAULTED_COMPONENT[right] in names]
            naming = ", ".join(hits) or "none"
            beyond_text = ", ".join(f"**{r}**" if r in hits else r for r in beyond) or "none"
            named += bool(hits)
            named_beyond += any(r in hits for r in beyond)
        sizes = "no (hours and share only)" if not row["size_metrics"] else ", ".join(row["size_metrics"])
        lines.append(f"| {row['day'][5:]} | {fault} | {fired} | {naming} | {beyond_text} | {sizes} |")
    faulted = sum(r["day"] in FAULTS for r in rows)
    missing = sorted({role for row in rows for role in row["missing_roles"]})
    lines += ["", f"Faulted days with a fired rule naming the faulted component: {named}/{faulted}; with one "
              f"firing beyond the unfaulted days (bold): {named_beyond}/{faulted}. Unfaulted days with some "
              f"rule fired: {alarms}/{len(rows) - faulted}.",
              f"Roles with no column (rules skipped): {', '.join(missing)}."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--days", nargs="+", default=sorted([*FAULTS, *UNFAULTED]), help="ISO dates (default: all 11)")
    args = parser.parse_args()
    if not SZVAV.is_file():
        sys.exit(f"skipped: {SZVAV} is absent (the FLEXLAB data live in ../shared/realdata)")
    check_mapping()
    frame = role_frame()
    print(table([run_day(frame, day) for day in args.days]))


if __name__ == "__main__":
    main()
