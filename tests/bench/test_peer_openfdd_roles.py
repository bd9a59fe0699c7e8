"""The peer bench's mapping (``bench_peer_openfdd.py``) against the FLEXLAB header it maps. (That the
roles and rules it names are open-fdd's is checked by the bench itself, which needs the ``bench``
extra: the suite does not install the peer.)"""

import csv

import pytest
from bench_peer_openfdd import COLUMN_ROLES
from shared_data import SZVAV


@pytest.mark.skipif(not SZVAV.is_file(), reason=f"{SZVAV} is absent (the FLEXLAB data live in ../shared/realdata)")
def test_every_mapped_column_is_in_the_flexlab_header():
    with SZVAV.open(newline="", encoding="utf-8") as handle:
        header = {name.strip() for name in next(csv.reader(handle))}
    assert set(COLUMN_ROLES) <= header, sorted(set(COLUMN_ROLES) - header)

