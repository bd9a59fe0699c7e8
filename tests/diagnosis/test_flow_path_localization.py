"""Localisation along the flow path, including a recirculation loop and off-path sensors."""

from service.diagnosis.localization import FailureLocation, FlowTopology, describe_locations, localize_failures

# outdoor sensor → mixing box → fan → coil → supply sensor → room → return sensor → mixing box (loop)
LOOP = [
    ("oat", "mix"), ("mix", "mat"), ("mat", "fan"), ("fan", "coil"), ("coil", "sat"),
    ("sat", "room"), ("room", "rat"), ("rat", "mix"), ("hw_valve", "coil_water"), ("coil_water", "coil"),
    ("swt", "hw_valve"),
]
SENSORS = {"oat", "mat", "sat", "rat", "swt", "valve_pos"}


def test_failure_between_last_matching_and_first_failing_sensor_on_a_loop():
    topology = FlowTopology(LOOP, {"valve_pos": "hw_valve"})
    matches = {"oat": True, "mat": True, "sat": False, "rat": True, "swt": True}
    locations = {loc.matching_sensor: set(loc.components) for loc in localize_failures(topology, matches, SENSORS)}
    # the air branch from the mixed-air sensor, the water branch from the supply water sensor
    assert locations == {"mat": {"fan", "coil"}, "swt": {"hw_valve", "coil_water", "coil"}}


def test_a_location_bounded_by_a_boundary_input_does_not_say_the_model_matches_it():
    """The supply water temperature is fed to the model, not predicted: the model cannot fail there,
    and the location says it takes that measurement instead of claiming a match it never checked."""
    topology = FlowTopology(LOOP)
    matches = {"oat": True, "mat": True, "sat": False, "rat": True, "swt": True}
    locations = {loc.matching_sensor: loc for loc in localize_failures(topology, matches, SENSORS, inputs={"swt", "oat"})}
    assert locations["swt"].matching_is_input and not locations["mat"].matching_is_input
    assert locations["swt"].describe().startswith("The model fails at sat, downstream of swt, whose measurement it "
                                                  "takes as an input: the missing effect sits in ")
    assert locations["mat"].describe().startswith("The model matches mat but not sat")
    assert locations["swt"].to_dict()["upstream_is_input"] is True


def test_both_branches_reported_and_room_never_a_suspect_for_the_supply_sensor():
    topology = FlowTopology(LOOP)
    matches = {"oat": True, "mat": True, "sat": False, "rat": True, "swt": True}
    locations = localize_failures(topology, matches, SENSORS)
    suspects = {c for loc in locations for c in loc.components}
    assert {loc.matching_sensor for loc in locations} == {"mat", "swt"}
    assert suspects == {"fan", "coil", "hw_valve", "coil_water"}
    assert "room" not in suspects and "mix" not in suspects


def test_a_failure_inherited_from_upstream_is_not_reported_twice():
    topology = FlowTopology(LOOP)
    matches = {"oat": True, "mat": False, "sat": False, "rat": True, "swt": True}
    locations = localize_failures(topology, matches, SENSORS)
    # sat only inherits the mixed-air failure; mat is located at the mixing box from both branches
    assert {loc.failing_sensor for loc in locations} == {"mat"}
    assert {loc.matching_sensor: loc.components for loc in locations} == {"oat": ("mix",), "rat": ("mix",)}


def test_an_error_that_grows_past_a_failing_sensor_is_located_there_too():
    """On the FLEXLAB leak day the mixed air was 0.7 K off and the supply air 14 K: the supply air's
    failure is not the mixed air's carried down. Where the caller says the upstream failure does not
    carry it, the sensor is located between them (and still between the matching sensors and it)."""
    topology = FlowTopology(LOOP)
    matches = {"oat": True, "mat": False, "sat": False, "rat": True, "swt": True}
    locations = localize_failures(topology, matches, SENSORS, carries=lambda upstream, failing: failing != "sat")
    grown = [loc for loc in locations if loc.failing_sensor == "sat"]
    assert {(loc.matching_sensor, loc.upstream_fails, loc.components) for loc in grown} == {
        ("mat", True, ("coil", "fan")), ("swt", False, ("coil", "coil_water", "hw_valve"))}
    assert "The error grows from mat, which fails too, to sat" in next(loc for loc in grown if loc.upstream_fails).describe()
    assert {loc.failing_sensor for loc in locations} == {"mat", "sat"}
    carried = localize_failures(topology, matches, SENSORS, carries=lambda upstream, failing: True)
    assert {loc.failing_sensor for loc in carried} == {"mat"}


def test_off_path_sensor_is_placed_at_the_node_it_observes():
    topology = FlowTopology(LOOP, {"valve_pos": "hw_valve"})
    matches = {"swt": True, "valve_pos": False}
    [location] = localize_failures(topology, matches, SENSORS)
    assert location.matching_sensor == "swt"
    assert location.components == ("hw_valve",)
    assert "hw_valve" in location.describe() and "valve_pos" in location.describe()


def test_a_coils_water_outlet_has_the_air_side_upstream_among_its_suspects():
    """The case study: a coil's water side transfers heat to its air side. The air the coil heats
    decides the water leaving it, so a failing water outlet sensor is located between the coil
    inlet water sensor and it, and between the fan's inlet air sensor and it (the fan among the suspects)."""
    fluid = [("fan_inlet", "fan"), ("fan", "coil_air"), ("coil_air", "coil_outlet_air"),
             ("swt", "valve"), ("valve", "pump"), ("pump", "coil_inlet_water"), ("coil_inlet_water", "coil_water"),
             ("coil_water", "coil_outlet_water")]
    topology = FlowTopology(fluid, heat_couplings=[("coil_water", "coil_air")])
    sensors = {"fan_inlet", "coil_outlet_air", "swt", "coil_inlet_water", "coil_outlet_water"}
    matches = {s: s != "coil_outlet_water" for s in sensors}
    locations = {loc.matching_sensor: set(loc.components) for loc in localize_failures(topology, matches, sensors)}
    assert locations == {"coil_inlet_water": {"coil_water", "coil_air"}, "fan_inlet": {"fan", "coil_air", "coil_water"}}
    air_fails = {s: s != "coil_outlet_air" for s in sensors}  # the water side is still a suspect of the air outlet
    located = {loc.matching_sensor: set(loc.components) for loc in localize_failures(topology, air_fails, sensors)}
    assert located == {"fan_inlet": {"fan", "coil_air", "coil_water"}, "coil_inlet_water": {"coil_water", "coil_air"}}


def test_a_disturbance_a_controller_rejects_is_located_on_the_side_it_moves():
    """The case study's closed loop: a controller holds the coil outlet air temperature by moving the
    hot-water valve. Heat a fan adds upstream leaves that sensor matching and shows at the valve's
    position and the coil inlet water instead; through the loop, the fan and the coil's air side are
    among the suspects of both, and the location says so. Without the loop the walk from the water
    side never reaches the air path."""
    fluid = [("fan_inlet", "fan"), ("fan", "coil_air"), ("coil_air", "coil_outlet_air"),
             ("swt", "valve"), ("valve", "pump"), ("pump", "coil_inlet_water"), ("coil_inlet_water", "coil_water"),
             ("coil_water", "coil_outlet_water")]
    sensors = {"fan_inlet", "coil_outlet_air", "swt", "coil_inlet_water", "coil_outlet_water", "valve_pos"}
    matches = {s: s not in ("valve_pos", "coil_inlet_water") for s in sensors}
    owners = {"valve_pos": "valve"}

    def located(topology):
        return {(loc.failing_sensor, loc.matching_sensor): (set(loc.components), loc.through_controller_of)
                for loc in localize_failures(topology, matches, sensors)}

    open_loop = located(FlowTopology(fluid, owners, heat_couplings=[("coil_water", "coil_air")]))
    assert open_loop == {("coil_inlet_water", "swt"): ({"valve", "pump"}, None),
                         ("valve_pos", "swt"): ({"valve"}, None)}
    closed = FlowTopology(fluid, owners, heat_couplings=[("coil_water", "coil_air")],
                          control_loops=[("coil_outlet_air", "valve")])
    assert closed.control_edges == {("coil_air", "valve")}
    loop = located(closed)
    assert loop[("valve_pos", "fan_inlet")] == ({"fan", "coil_air", "coil_water", "valve"}, "valve")
    assert loop[("coil_inlet_water", "fan_inlet")] == ({"fan", "coil_air", "coil_water", "valve", "pump"}, "valve")
    assert loop[("valve_pos", "swt")] == ({"valve"}, None)  # the water path alone does not pass the loop
    describe = next(loc for loc in localize_failures(closed, matches, sensors)
                    if loc.matching_sensor == "fan_inlet" and loc.failing_sensor == "valve_pos").describe()
    assert "fan" in describe and "through the controller that moves valve" in describe


def test_the_diagnosis_carries_a_failure_down_only_where_the_residuals_say_so():
    import numpy as np

    from service.diagnosis.loop import _carried_down

    rng = np.random.default_rng(0)
    offset = np.where(np.arange(200) < 100, 0.0, 0.7)  # the mixed air 0.7 K off in the second half
    mixed = offset + rng.normal(0, 0.1, 200)
    degc = "http://qudt.org/vocab/unit/DEG_C"
    residuals = {"mat": mixed, "sat_same": offset + rng.normal(0, 0.1, 200),
                 "sat_grown": offset + np.where(np.arange(200) % 50 < 25, 14.0, 0.0) + rng.normal(0, 0.1, 200),
                 "power": offset * 100}
    residuals["mat"][:3] = np.nan  # steps without a measurement are left out of the comparison
    units = {"mat": degc, "sat_same": degc, "sat_grown": degc, "power": "http://qudt.org/vocab/unit/W"}
    noise = {"mat": 0.1, "sat_same": 0.1, "sat_grown": 0.1, "power": 5.0}
    carries = _carried_down(residuals, units, noise, failure_ratio=2.0)
    assert carries("mat", "sat_same") and not carries("mat", "sat_grown")
    assert carries("mat", "power")  # other units: cannot be told apart, carried


def test_a_sensor_failing_downstream_of_several_inputs_is_one_sentence_naming_them_all():
    """A coil's outlet air downstream of the measured air flow and the measured hot water was two
    sentences, one per input, each with its own suspects; a user read six bullets for three sensors."""
    ex = "https://example.org/x#"
    by_flow = FailureLocation(ex + "sat", ex + "air_flow", (ex + "fan", ex + "coil"), matching_is_input=True)
    by_water = FailureLocation(ex + "sat", ex + "water_temperature", (ex + "pump", ex + "coil"), matching_is_input=True)
    matched = FailureLocation(ex + "return_water", ex + "supply_water", (ex + "coil",))
    assert describe_locations([by_flow, matched, by_water]) == [
        "The model fails at sat, downstream of air_flow and water_temperature, whose measurements it takes as "
        "inputs: the missing effect sits in fan or coil or pump between them.",
        matched.describe(),
    ]
    assert describe_locations([by_flow]) == [by_flow.describe()]
    assert "whose measurement it takes as an input" in by_flow.describe()
