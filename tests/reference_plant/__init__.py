"""An independent reference plant: the case-study ventilation unit (supply fan, hot-water heating
coil, two-way valve, pump, check valve, PI control of the coil outlet air) simulated from first
principles, sharing no code with ``service/``, to test graphtwin's diagnosis against physics it
did not write.

Physics and units (SI inside; °C, m³/s air, m³/h for a valve's Kv, W, s):

* outdoor air: daily sinusoid + day-to-day level + AR(1) weather noise; a counter-flow heat
  recovery (ε = NTU/(1 + NTU), NTU ∝ flow^−0.2) gives the fan inlet temperature;
* VSD fan: flow schedule (occupied, night, weekend), P from air power V·Δp over a system curve with
  a fixed part, impeller and part-load motor/drive efficiencies; impeller losses heat the air;
* water circuit: constant-speed pump curve, coil and pipes k·Q², check valve cracking pressure,
  equal-percentage valve (R = 50; its authority follows from the circuit) plus a seat leak path;
  plug-flow pipes with transport delay volume / flow and heat loss to the plant room;
* coil: counter-flow ε-NTU, film conductances ∝ flow^0.8 each side, lumped metal heat capacity;
* PI controller sampled every 30 s, anti-windup by conditional integration, actuator rate limit;
  setpoint steps day/night/weekend; supply water from an outdoor-reset curve with noise;
* sensors: response lags, Gaussian noise 0.15 K and 0.1 K quantisation for temperatures, 2 % of the
  reading for flow and power; the BMS trend stores instants (temperatures, position) and means
  over the step (flow, power) every 10 min.

Faults (``faults.FAULTS``) are injected where the real fault sits, from a start time; the truth
is returned apart from the data. ``python -m tests.reference_plant --help`` writes a CSV.
"""

from .csv_output import write_plant_csv, write_run_csv
from .faults import FAULTS, Fault, FaultKind, FaultTruth
from .plant import PlantRun, PlantSettings, simulate_plant

__all__ = ["FAULTS", "Fault", "FaultKind", "FaultTruth", "PlantRun", "PlantSettings", "simulate_plant",
           "write_plant_csv", "write_run_csv"]
