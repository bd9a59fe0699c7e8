"""The faults the plant can carry, each with its size parameter, the node of the case-study graph
it acts at (the IRI's local name) and the plain-language name of the catalog effect it corresponds
to (None: outside the catalog).

Sizes: valve leakage, the seat's Kv as a fraction of Kvs; valve stuck, the stem position (0–1) it
sticks at; sensor offset, K; sensor lag, the added time constant in s; fan motor heat, the extra
fraction of the electric power heating the air on top of the impeller's losses (0.27–0.31 of it: at
most ~0.69 can be added before the air receives more heat than the fan draws); constant heat gain,
W into the air; duct heat exchange, the casing's UA in W/K to a space (the case-study graph has
none); coil thermal mass, the factor on the coil's metal heat capacity; coil fouling, the fraction
of UA lost per day; supply pipe heat loss, the pipe's added UA in W/K.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FaultKind", "FAULTS", "Fault", "FaultTruth"]


@dataclass(frozen=True, kw_only=True)
class FaultKind:
    """One kind of fault: ``clear`` and ``subtle`` sizes for a validation matrix; ``appears``: it
    can start mid-data (False: a property of the equipment, present from the start)."""

    name: str
    catalog_effect: str | None
    node: str
    size_unit: str
    clear: float
    subtle: float
    appears: bool


FAULTS: dict[str, FaultKind] = {kind.name: kind for kind in (
    FaultKind(name="valve_leakage", catalog_effect="valve leakage", node="heating_valve",
              size_unit="fraction of Kvs", clear=0.10, subtle=0.03, appears=True),
    FaultKind(name="valve_stuck", catalog_effect="valve stuck", node="heating_valve",
              size_unit="stem position", clear=0.60, subtle=0.25, appears=True),
    FaultKind(name="sensor_offset", catalog_effect="temperature sensor offset",
              node="coil_outlet_air_temperature_sensor", size_unit="K", clear=1.5, subtle=0.4, appears=True),
    FaultKind(name="sensor_lag", catalog_effect="temperature sensor lag",
              node="coil_outlet_water_temperature_sensor", size_unit="s", clear=900.0, subtle=240.0, appears=False),
    FaultKind(name="fan_motor_heat", catalog_effect="fan motor heat", node="supply_fan",
              size_unit="fraction of electric power", clear=0.6, subtle=0.3, appears=False),
    FaultKind(name="constant_heat_gain", catalog_effect="constant heat gain", node="heating_coil_air_side",
              size_unit="W", clear=3000.0, subtle=1000.0, appears=True),
    FaultKind(name="duct_heat_exchange", catalog_effect="duct heat exchange", node="heating_coil_air_side",
              size_unit="W/K", clear=150.0, subtle=50.0, appears=False),
    FaultKind(name="coil_thermal_mass", catalog_effect="coil thermal mass", node="heating_coil_air_side",
              size_unit="factor on metal heat capacity", clear=8.0, subtle=3.0, appears=False),
    FaultKind(name="coil_fouling", catalog_effect=None, node="heating_coil_air_side",
              size_unit="fraction of UA lost per day", clear=0.08, subtle=0.03, appears=True),
    FaultKind(name="supply_pipe_heat_loss", catalog_effect=None, node="pump",
              size_unit="W/K", clear=25.0, subtle=10.0, appears=True),
)}


@dataclass(frozen=True, kw_only=True)
class FaultTruth:
    """What was injected, kept apart from the data: the fault kind (None: fault-free), its size,
    the node (local name in the case-study graph), the catalog effect's plain name and the start."""

    fault: str | None
    size: float
    node: str | None
    catalog_effect: str | None
    start: np.datetime64 | None

    def to_dict(self) -> dict:
        return {"fault": self.fault, "size": self.size, "node": self.node, "catalog_effect": self.catalog_effect,
                "start": None if self.start is None else str(self.start)}


@dataclass(frozen=True, kw_only=True)
class Fault:
    """A fault to inject: its kind's name, size and start (s from the simulation start; 0: from the
    beginning). :meth:`active` is 1.0 from the start on, as a mask over the grid ``t_s``."""

    name: str
    size: float
    start_s: float = 0.0

    def __post_init__(self):
        if self.name not in FAULTS:
            raise ValueError(f"unknown fault {self.name!r}; known: {', '.join(FAULTS)}")

    @property
    def kind(self) -> FaultKind:
        return FAULTS[self.name]

    def active(self, t_s: np.ndarray) -> np.ndarray:
        return (np.asarray(t_s) >= self.start_s).astype(float)
