"""A generated campus of air handling units for the signature matching benchmark.

Every unit is written in the style of the case-study model (``service/examples``): SAREF4BLDG
classes, FSO flow path (``fso:suppliesFluidTo``), SAREF properties and nominal-value chains. The
measuring devices are also typed with the classes the alignment step derives (``gt:TemperatureSensor``,
``gt:FlowSensor``, ``gt:PowerMeter``, ``gt:PositionSensor``), so the graph can be matched without
running the alignment rules. One unit, in flow order::

    outdoor air sensor → duct → OA damper → mixing box → mixed air sensor → filter → duct
      → heating coil (air side) → cooling coil → supply flow meter → supply fan → duct
      → supply air sensor → supply duct → branch k → VAV damper k → room k  (k = 1..n_rooms)
      → return duct → return air sensor → return flow meter → return fan
      → return damper → mixing box                       (the recirculation loop)
                                   └→ exhaust damper
    hot-water loop: substation → supply pipe → supply water sensor → heating valve → pump
      → coil inlet water sensor → heating coil (water side) → coil outlet water sensor
      → check valve → return pipe → substation           (a second loop)

plus commands for the dampers, power meters on both fans and the pump, a
valve position sensor, a room sensor per room, and a plant room that contains the heating coil (with
its air temperature sensor). Even-numbered units heat like the case study (the water loop above, a PI
controller on the heating valve with its setpoint schedule) and cool under a second controller on the
cooling valve; odd-numbered units like the FLEXLAB AHU (``service/examples/flexlab_ahu``): a
``gt:HeatingCoil`` fed by a commanded valve, no water loop, a commanded cooling valve and a supply fan
with a commanded speed. Ducts and pipes (``fso:Segment``) sit between equipment, so
traverses take several hops, and every signature of ``signatures/`` has matches.

    python tests/bench/campus_graph.py --ahus 2 > campus.ttl
"""

from __future__ import annotations

import argparse
import sys

import pyoxigraph as ox

__all__ = ["CAMPUS_NAMESPACE", "PREFIXES", "ahu_turtle", "campus_turtle", "triples_per_ahu", "ahus_for_triples"]

#: Unit ``i``'s resources live in ``CAMPUS_NAMESPACE + "ahu{i}#"``.
CAMPUS_NAMESPACE = "https://example.org/campus/"

PREFIXES = """\
@prefix saref:  <https://saref.etsi.org/core/> .
@prefix s4bldg: <https://saref.etsi.org/saref4bldg/> .
@prefix fso:    <https://w3id.org/fso#> .
@prefix gt:     <https://w3id.org/graphtwin/ontology#> .
@prefix unit:   <http://qudt.org/vocab/unit/> .
@prefix rdfs:   <http://www.w3.org/2000/01/rdf-schema#> .
@prefix xsd:    <http://www.w3.org/2001/XMLSchema#> .
"""


def _sensor(name: str, prop: str, prop_class: str, device_classes: str, unit: str, series: str, feeds: str | None) -> str:
    flow = f" ;\n    fso:suppliesFluidTo {feeds}" if feeds else ""
    return (
        f"{name} a {device_classes} ;\n    saref:observes {prop} ;\n    saref:isMeasuredIn {unit} ;\n"
        f'    gt:timeSeriesId "{series}"{flow} .\n{prop} a {prop_class} .\n'
    )


def _temperature_sensor(name: str, series: str, feeds: str | None) -> str:
    return _sensor(f"a:{name}", f"a:{name}_temperature", "saref:Temperature", "s4bldg:Sensor, gt:TemperatureSensor",
                   "unit:DEG_C", series, feeds)


def _command(target_property: str, series: str) -> str:
    return (
        f"{target_property}_command a gt:CommandSignal ;\n    saref:controls {target_property} ;\n"
        f'    saref:isMeasuredIn unit:UNITLESS ;\n    gt:timeSeriesId "{series}" .\n'
        f"{target_property} a gt:OpeningPosition .\n"
    )


def _nominal(owner: str, name: str, kind: str, value: float, unit: str) -> str:
    return (
        f"{owner} saref:hasPropertyValue {owner}_{name} .\n"
        f"{owner}_{name} a saref:PropertyValue ;\n    saref:isValueOfProperty s4bldg:{kind} ;\n"
        f'    saref:hasValue "{value}"^^xsd:double ;\n    saref:isMeasuredIn {unit} .\n'
    )


def _fan(name: str, series: str, feeds: str, nominal_flow: float) -> str:
    return (
        f"a:{name} a s4bldg:Fan ;\n    saref:hasProperty a:{name}_power ;\n    fso:suppliesFluidTo {feeds} .\n"
        + _nominal(f"a:{name}", "nominal_air_flow", "nominalAirFlowRate", nominal_flow, "unit:M3-PER-SEC")
        + _nominal(f"a:{name}", "nominal_power", "nominalPowerRate", round(1.2 * nominal_flow, 3), "unit:KiloW")
        + _sensor(f"a:{name}_power_meter", f"a:{name}_power", "saref:Power", "saref:Meter, gt:PowerMeter",
                  "unit:W", f"{series}_power", None)
    )


def ahu_turtle(index: int, n_rooms: int = 8) -> str:
    """The Turtle of unit ``index`` (prefix ``a:`` is declared as its namespace; even ``index``: case-study
    heating, odd: FLEXLAB heating, see the module docstring)."""
    if n_rooms < 1:
        raise ValueError(f"n_rooms must be at least 1, got {n_rooms}")
    tag = f"ahu{index}"
    flow = 0.4 * n_rooms
    flexlab = index % 2 == 1
    parts = [
        f"@prefix a: <{CAMPUS_NAMESPACE}{tag}#> .\n",
        f'a:ahu a fso:SupplySystem ;\n    rdfs:label "Air handling unit {index}" ;\n'
        "    fso:hasComponent a:outdoor_air_damper, a:mixing_box, a:filter, a:heating_coil_air_side, "
        "a:cooling_coil, a:supply_fan, a:return_fan .\n",
        # outdoor air
        "a:outdoors a gt:OutdoorEnvironment ;\n    saref:hasProperty a:outdoor_air_sensor_temperature .\n",
        _temperature_sensor("outdoor_air_sensor", f"{tag}/outdoor_air_temperature", "a:outdoor_air_duct"),
        "a:outdoor_air_duct a fso:Segment ;\n    fso:suppliesFluidTo a:outdoor_air_damper .\n",
        "a:outdoor_air_damper a s4bldg:Damper ;\n    saref:hasProperty a:outdoor_air_damper_position ;\n"
        "    fso:suppliesFluidTo a:mixing_box .\n",
        _command("a:outdoor_air_damper_position", f"{tag}/outdoor_air_damper_command"),
        # mixing, filter, coils, supply fan
        "a:mixing_box a gt:MixingBox ;\n    fso:suppliesFluidTo a:mixed_air_sensor .\n",
        _temperature_sensor("mixed_air_sensor", f"{tag}/mixed_air_temperature", "a:filter"),
        "a:filter a s4bldg:Filter ;\n    fso:suppliesFluidTo a:coil_duct .\n",
        _nominal("a:filter", "nominal_flow", "nominalFlowRate", flow, "unit:M3-PER-SEC"),
        "a:coil_duct a fso:Segment ;\n    fso:suppliesFluidTo a:heating_coil_air_side .\n",
        f"a:heating_coil_air_side a {'gt:HeatingCoil' if flexlab else 's4bldg:Coil'} ;\n"
        "    fso:suppliesFluidTo a:cooling_coil .\n",
        "a:cooling_coil a gt:CoolingCoil ;\n    fso:suppliesFluidTo a:supply_flow_meter .\n",
        "a:cooling_valve a s4bldg:Valve ;\n    saref:hasProperty a:cooling_valve_position ;\n"
        "    fso:suppliesFluidTo a:cooling_coil .\n",
        _sensor("a:supply_flow_meter", "a:supply_air_flow", "gt:FlowRate", "s4bldg:FlowMeter, gt:FlowSensor",
                "unit:M3-PER-SEC", f"{tag}/supply_air_flow", "a:supply_fan"),
        _fan("supply_fan", f"{tag}/supply_fan", "a:supply_fan_duct", flow),
        "a:supply_fan_duct a fso:Segment ;\n    fso:suppliesFluidTo a:supply_air_sensor .\n",
        _temperature_sensor("supply_air_sensor", f"{tag}/supply_air_temperature", "a:supply_duct"),
        "a:supply_duct a fso:Segment .\n",
        # rooms
        "a:return_duct a fso:Segment ;\n    fso:suppliesFluidTo a:return_air_sensor .\n",
    ]
    for k in range(1, n_rooms + 1):
        parts += [
            f"a:supply_duct fso:suppliesFluidTo a:branch_{k} .\n",
            f"a:branch_{k} a fso:Segment ;\n    fso:suppliesFluidTo a:vav_damper_{k} .\n",
            f"a:vav_damper_{k} a s4bldg:Damper ;\n    saref:hasProperty a:vav_damper_{k}_position ;\n"
            f"    fso:suppliesFluidTo a:room_{k} .\n",
            _command(f"a:vav_damper_{k}_position", f"{tag}/vav_damper_{k}_command"),
            f'a:room_{k} a s4bldg:BuildingSpace ;\n    rdfs:label "Room {k} of unit {index}" ;\n'
            f"    saref:hasProperty a:room_{k}_sensor_temperature ;\n    fso:suppliesFluidTo a:return_duct .\n",
            _temperature_sensor(f"room_{k}_sensor", f"{tag}/room_{k}_temperature", None),
        ]
    parts += [
        # return path and the recirculation loop
        _temperature_sensor("return_air_sensor", f"{tag}/return_air_temperature", "a:return_flow_meter"),
        _sensor("a:return_flow_meter", "a:return_air_flow", "gt:FlowRate", "s4bldg:FlowMeter, gt:FlowSensor",
                "unit:M3-PER-SEC", f"{tag}/return_air_flow", "a:return_fan"),
        _fan("return_fan", f"{tag}/return_fan", "a:return_fan_duct", round(0.9 * flow, 3)),
        "a:return_fan_duct a fso:Segment ;\n    fso:suppliesFluidTo a:return_air_damper, a:exhaust_air_damper .\n",
        "a:return_air_damper a s4bldg:Damper ;\n    saref:hasProperty a:return_air_damper_position ;\n"
        "    fso:suppliesFluidTo a:mixing_box .\n",
        _command("a:return_air_damper_position", f"{tag}/return_air_damper_command"),
        "a:exhaust_air_damper a s4bldg:Damper ;\n    saref:hasProperty a:exhaust_air_damper_position .\n",
        _command("a:exhaust_air_damper_position", f"{tag}/exhaust_air_damper_command"),
        # the plant room around the heating coil
        "a:plant_room a s4bldg:BuildingSpace ;\n    s4bldg:contains a:heating_coil_air_side ;\n"
        "    saref:hasProperty a:plant_room_sensor_temperature .\n",
        _temperature_sensor("plant_room_sensor", f"{tag}/plant_room_temperature", None),
    ]
    parts += _flexlab_heating(tag) if flexlab else _case_study_heating(tag)
    return "".join(parts)


def _flexlab_heating(tag: str) -> list[str]:
    """A commanded heating valve straight onto the coil, and the supply fan's commanded speed."""
    return [
        "a:heating_valve a s4bldg:Valve ;\n    saref:hasProperty a:heating_valve_position ;\n"
        "    fso:suppliesFluidTo a:heating_coil_air_side .\n",
        _command("a:heating_valve_position", f"{tag}/heating_valve_command"),
        _command("a:cooling_valve_position", f"{tag}/cooling_valve_command"),
        "a:supply_fan saref:hasProperty a:supply_fan_speed .\na:supply_fan_speed a gt:Speed .\n",
        f'a:supply_fan_speed_command a gt:CommandSignal ;\n    saref:controls a:supply_fan_speed ;\n'
        f'    saref:isMeasuredIn unit:UNITLESS ;\n    gt:timeSeriesId "{tag}/supply_fan_speed_command" .\n',
    ]


def _case_study_heating(tag: str) -> list[str]:
    """The case study's hot-water loop (a second loop) and the PI controller on its valve."""
    return [
        # hot-water loop
        "a:heating_loop a fso:SupplySystem ;\n    fso:hasComponent a:heating_valve, a:pump, a:heating_coil_water_side, "
        "a:check_valve .\n",
        "a:substation a s4bldg:HeatExchanger ;\n    fso:suppliesFluidTo a:supply_pipe .\n",
        "a:supply_pipe a fso:Segment ;\n    fso:suppliesFluidTo a:supply_water_sensor .\n",
        _temperature_sensor("supply_water_sensor", f"{tag}/supply_water_temperature", "a:heating_valve"),
        "a:heating_valve a s4bldg:Valve ;\n    saref:hasProperty a:heating_valve_position ;\n"
        "    fso:suppliesFluidTo a:pump .\n",
        "a:heating_valve_position a gt:OpeningPosition .\n",
        _nominal("a:heating_valve", "flow_coefficient", "flowCoefficient", 2.5, "unit:M3-PER-HR"),
        _sensor("a:valve_position_sensor", "a:heating_valve_position", "gt:OpeningPosition",
                "s4bldg:Sensor, gt:PositionSensor", "unit:UNITLESS", f"{tag}/valve_position", None),
        "a:pump a s4bldg:Pump ;\n    saref:hasProperty a:pump_power ;\n    fso:suppliesFluidTo a:coil_inlet_water_sensor .\n",
        _sensor("a:pump_power_meter", "a:pump_power", "saref:Power", "saref:Meter, gt:PowerMeter", "unit:W",
                f"{tag}/pump_power", None),
        _temperature_sensor("coil_inlet_water_sensor", f"{tag}/coil_inlet_water_temperature", "a:heating_coil_water_side"),
        "a:heating_coil_water_side a s4bldg:Coil ;\n    fso:transfersHeatTo a:heating_coil_air_side ;\n"
        "    fso:suppliesFluidTo a:coil_outlet_water_sensor .\n",
        _temperature_sensor("coil_outlet_water_sensor", f"{tag}/coil_outlet_water_temperature", "a:check_valve"),
        'a:check_valve a s4bldg:Valve ;\n    s4bldg:valveMechanism "check" ;\n    fso:suppliesFluidTo a:return_pipe .\n',
        "a:return_pipe a fso:Segment ;\n    fso:suppliesFluidTo a:substation .\n",
        # control
        "a:supply_air_controller a s4bldg:Controller ;\n    saref:observes a:supply_air_sensor_temperature ;\n"
        "    saref:controls a:heating_valve_position ;\n    saref:hasProfile a:setpoint_schedule .\n",
        'a:setpoint_schedule a gt:SetpointSchedule ;\n    saref:isMeasuredIn unit:DEG_C ;\n'
        f'    gt:timeSeriesId "{tag}/supply_air_temperature_setpoint" .\n',
        "a:cooling_valve_position a gt:OpeningPosition .\n",
        "a:cooling_controller a s4bldg:Controller ;\n    saref:observes a:supply_air_sensor_temperature ;\n"
        "    saref:controls a:cooling_valve_position ;\n    saref:hasProfile a:cooling_setpoint_schedule .\n",
        'a:cooling_setpoint_schedule a gt:SetpointSchedule ;\n    saref:isMeasuredIn unit:DEG_C ;\n'
        f'    gt:timeSeriesId "{tag}/supply_air_cooling_setpoint" .\n',
    ]


def campus_turtle(n_ahus: int, n_rooms: int = 8) -> str:
    """``n_ahus`` units (``ahu0`` … ``ahu{n_ahus-1}``), each with ``n_rooms`` rooms, as one Turtle document."""
    if n_ahus < 1:
        raise ValueError(f"n_ahus must be at least 1, got {n_ahus}")
    return PREFIXES + "".join(ahu_turtle(i, n_rooms) for i in range(n_ahus))


def triples_per_ahu(n_rooms: int = 8) -> float:
    """Triples per unit, averaged over a case-study and a FLEXLAB unit."""
    return sum(1 for _ in ox.parse(campus_turtle(2, n_rooms).encode(), format=ox.RdfFormat.TURTLE)) / 2


def ahus_for_triples(target_triples: int, n_rooms: int = 8) -> int:
    """The number of units whose campus has about ``target_triples`` triples (at least one unit)."""
    return max(1, round(target_triples / triples_per_ahu(n_rooms)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ahus", type=int, default=1)
    parser.add_argument("--rooms", type=int, default=8)
    args = parser.parse_args()
    sys.stdout.write(campus_turtle(args.ahus, args.rooms))


if __name__ == "__main__":
    main()
