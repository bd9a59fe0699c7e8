"""A generated Brick campus for the alignment benchmark (tests/bench/bench_brick_alignment.py).

Unit ``i`` lives in ``CAMPUS_NAMESPACE + "ahu{i}#"`` and is one of two kinds:

* a complete unit: the Brick FLEXLAB AHU of ``service/examples/flexlab_ahu_brick/model.ttl`` (parts
  with ``brick:hasPart``, ``brick:feeds`` chain, points on the unit and on the equipment, QUDT units,
  ``ref:hasTimeseriesId`` columns) whose supply fan feeds ``n_zones`` VAV terminal units, each with a
  damper, its position command, an air flow sensor, a discharge air temperature sensor and a room
  with a zone air temperature sensor and a setpoint (a point no rule aligns);
* every ``points_only_every``-th unit is described by its points only (as a BMS export writes it,
  e.g. open-fdd's school AHU): the alignment mints its equipment.

    python tests/bench/brick_campus.py --units 2 > campus.ttl
"""

from __future__ import annotations

import argparse
import sys

import pyoxigraph as ox

from service.resources import examples_dir

__all__ = ["CAMPUS_NAMESPACE", "campus_turtle", "triples_per_unit", "units_for_triples"]

CAMPUS_NAMESPACE = "https://example.org/brick-campus/"
_FLEXLAB = (examples_dir() / "flexlab_ahu_brick" / "model.ttl").read_text(encoding="utf-8")
_PREFIXES = "\n".join(line for line in _FLEXLAB.splitlines() if line.startswith("@prefix") and " ex:" not in line)
_FLEXLAB_BODY = "\n".join(line for line in _FLEXLAB.splitlines() if not line.startswith(("@prefix", "#")))

_ZONE = """
ex:vav{k} a brick:VAV ; brick:isFedBy ex:supply_fan ; brick:hasPart ex:vav{k}_damper ; brick:feeds ex:room{k} ;
    brick:hasPoint ex:vav{k}_flow, ex:vav{k}_dat .
ex:vav{k}_damper a brick:Damper ; brick:hasPoint ex:vav{k}_damper_command .
ex:vav{k}_damper_command a brick:Damper_Position_Command ; brick:hasUnit unit:PERCENT ;
    ref:hasExternalReference [ ref:hasTimeseriesId "vav{k}_damper_command" ] .
ex:vav{k}_flow a brick:Supply_Air_Flow_Sensor ; brick:hasUnit unit:M3-PER-SEC ;
    ref:hasExternalReference [ ref:hasTimeseriesId "vav{k}_flow" ] .
ex:vav{k}_dat a brick:Discharge_Air_Temperature_Sensor ; brick:hasUnit unit:DEG_C ;
    ref:hasExternalReference [ ref:hasTimeseriesId "vav{k}_dat" ] .
ex:room{k} a rec:Office ; brick:hasPoint ex:room{k}_temperature, ex:room{k}_setpoint .
ex:room{k}_temperature a brick:Zone_Air_Temperature_Sensor ; brick:hasUnit unit:DEG_C ;
    ref:hasExternalReference [ ref:hasTimeseriesId "room{k}_temperature" ] .
ex:room{k}_setpoint a brick:Zone_Air_Temperature_Setpoint ; brick:hasUnit unit:DEG_C .
"""

_POINTS_ONLY = """
ex:ahu a brick:Air_Handling_Unit .
ex:oat a brick:Outside_Air_Temperature_Sensor ; brick:isPointOf ex:ahu ; brick:hasUnit unit:DEG_F ; rdfs:label "OAT" .
ex:rat a brick:Return_Air_Temperature_Sensor ; brick:isPointOf ex:ahu ; brick:hasUnit unit:DEG_F ; rdfs:label "RAT" .
ex:mat a brick:Mixed_Air_Temperature_Sensor ; brick:isPointOf ex:ahu ; brick:hasUnit unit:DEG_F ; rdfs:label "MAT" .
ex:sat a brick:Supply_Air_Temperature_Sensor ; brick:isPointOf ex:ahu ; brick:hasUnit unit:DEG_F ; rdfs:label "SAT" .
ex:oa_cmd a brick:Damper_Position_Command ; brick:isPointOf ex:ahu ; brick:hasUnit unit:PERCENT ; rdfs:label "OA Dmp Cmd" .
ex:clg_cmd a brick:Valve_Command ; brick:isPointOf ex:ahu ; brick:hasUnit unit:PERCENT ; rdfs:label "Clg Vlv Cmd" .
ex:htg_cmd a brick:Valve_Command ; brick:isPointOf ex:ahu ; brick:hasUnit unit:PERCENT ; rdfs:label "Prht Vlv Cmd" .
ex:sf_cmd a brick:Fan_Speed_Command ; brick:isPointOf ex:ahu ; brick:hasUnit unit:PERCENT ; rdfs:label "SF Spd Cmd" .
ex:sat_sp a brick:Supply_Air_Temperature_Setpoint ; brick:isPointOf ex:ahu ; brick:hasUnit unit:DEG_F ; rdfs:label "SAT Sp" .
"""


def _unit(i: int, n_zones: int, points_only: bool) -> str:
    body = _POINTS_ONLY if points_only else _FLEXLAB_BODY + "".join(_ZONE.format(k=k) for k in range(n_zones))
    return f"@prefix ex: <{CAMPUS_NAMESPACE}ahu{i}#> .\n{body}"


def campus_turtle(n_units: int, *, n_zones: int = 4, points_only_every: int = 10) -> str:
    """``n_units`` units (every ``points_only_every``-th described by its points only), one Turtle text."""
    units = (_unit(i, n_zones, points_only_every > 0 and i % points_only_every == points_only_every - 1)
             for i in range(n_units))
    return _PREFIXES + "\n" + "\n".join(units)


def triples_per_unit(*, n_zones: int = 4, points_only_every: int = 10) -> float:
    """Mean triple count of one unit over a cycle of ``points_only_every`` units."""
    cycle = max(points_only_every, 1)
    text = campus_turtle(cycle, n_zones=n_zones, points_only_every=points_only_every)
    return len(list(ox.parse(text.encode(), format=ox.RdfFormat.TURTLE))) / cycle


def units_for_triples(n_triples: int, **kwargs) -> int:
    return max(1, round(n_triples / triples_per_unit(**kwargs)))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--units", type=int, default=1)
    parser.add_argument("--zones", type=int, default=4)
    args = parser.parse_args()
    sys.stdout.write(campus_turtle(args.units, n_zones=args.zones))
