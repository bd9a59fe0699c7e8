"""A valve actuator's dead band: the stem it sets for a command, and the command that sets a stem.

    stem = clip((u − u₀)/(1 − u₀), 0, 1)                                              [1]

u the command (0–1), u₀ the dead band (a 2–10 V actuator on a 0–10 V output: u₀ = 0.2). Faults of
the valve itself (a seat that leaks, a stem that sticks) act on the stem, past the dead band; an
effect spliced on the command computes the stem, changes it, and returns the command that sets the
changed stem (:func:`command_for_stem`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["DEAD_BAND_PARAMETER", "act_on_stem", "actuator_stem_position", "command_for_stem"]

#: The host parameter a valve effect reads (``ComponentModel.host_parameters``) for the dead band u₀.
DEAD_BAND_PARAMETER = "valve_dead_band"


def actuator_stem_position(command, dead_band):
    """The stem position [1] the actuator sets for ``command`` behind its ``dead_band`` u₀."""
    return np.minimum(np.maximum((command - dead_band) / (1.0 - dead_band), 0.0), 1.0)


def command_for_stem(stem, command, dead_band):
    """The command [1] that sets ``stem`` behind ``dead_band``: u₀ + (1 − u₀)·stem for an open stem;
    for a shut one, ``command`` itself where it lies inside the dead band (else u₀)."""
    return np.where(stem > 0.0, dead_band + (1.0 - dead_band) * stem, np.minimum(command, dead_band))


def act_on_stem(command, params, change):
    """The command [1] that gives the stem ``change(stem)``: past the dead band ``params`` hold (the
    host's, :data:`DEAD_BAND_PARAMETER`), or ``change(command)`` itself where they hold none."""
    if DEAD_BAND_PARAMETER not in params:
        return change(command)
    dead_band = params[DEAD_BAND_PARAMETER]
    return command_for_stem(change(actuator_stem_position(command, dead_band)), command, dead_band)
