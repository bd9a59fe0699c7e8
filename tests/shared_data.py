"""Where the workplace's shared files lie (``../shared`` beside the project: the official ontology
files and the measured AHU data, never committed here). A test that needs one skips, naming the
path, when it is absent."""

from pathlib import Path

SHARED = Path(__file__).resolve().parents[2] / "shared"
OFFICIAL_ONTOLOGIES = SHARED / "ontologies"
OFFICIAL_BRICK = OFFICIAL_ONTOLOGIES / "brick" / "Brick.ttl"
#: LBNL FLEXLAB single-zone AHU, 1-minute, °F, with dated faults
SZVAV = SHARED / "realdata" / "lbnl_flexlab_single_zone_ahu" / "SZVAV.csv"
#: open-fdd's school AHU 7: a Brick model and 15-minute °F data
SCHOOL = SHARED / "realdata" / "openfdd_ahu7_school"
