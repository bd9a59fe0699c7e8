"""The ontology files: the subsets use official IRIs and official axioms; every gt: term is documented
and every gt: term the project uses is declared."""

import re
from collections import defaultdict

import pyoxigraph as ox
import pytest
from shared_data import OFFICIAL_ONTOLOGIES

from service.graph.namespaces import GT, OWL, RDF, RDFS, Namespace
from service.resources import ontologies_dir, project_home

SHARED = OFFICIAL_ONTOLOGIES
OFFICIAL_NAMESPACES = ("https://saref.etsi.org/", "https://w3id.org/fso#", "https://brickschema.org/schema/Brick",
                       "https://w3id.org/rec#")
#: The current releases the subsets follow (see each subset's header comment).
V4_FILES = ("saref/saref-core-v4.1.1.ttl", "saref/saref4bldg-v2.1.1.ttl", "saref/saref4syst-v1.1.2.ttl", "fso/fso.ttl",
            "brick/Brick.ttl")
V3_FILES = ("saref/saref-core-v3.1.1.ttl", "saref/saref4bldg-v1.1.2.ttl", "saref/saref4syst-v1.1.2.ttl")
#: Terms the subsets take from SAREF v3.1.1 because v4.1.1 deleted them (models written in v3 use them).
V3_ONLY = {
    "https://saref.etsi.org/core/Temperature", "https://saref.etsi.org/core/Power",
    "https://saref.etsi.org/core/measuresProperty", "https://saref.etsi.org/core/controlsProperty",
}
#: FSO's alignment files declare these namespaces with '#'; the real SAREF namespaces end in '/'.
ALIGNMENT_FILES = ("fso/SAREF4BLDGAlignment.ttl", "fso/SAREF4SYSTAlignment.ttl")
NAMESPACE_FIXES = {b"https://saref.etsi.org/saref4bldg#": b"https://saref.etsi.org/saref4bldg/",
                   b"https://saref.etsi.org/saref4syst#": b"https://saref.etsi.org/saref4syst/"}

needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason=f"official ontology files not found at {SHARED}")


def _triples(data: bytes) -> list[ox.Triple]:
    return [ox.Triple(q.subject, q.predicate, q.object) for q in ox.parse(data, format=ox.RdfFormat.TURTLE)]


def _official(names) -> list[ox.Triple]:
    return [t for name in names for t in _triples((SHARED / name).read_bytes())]


def _fixed(alignment: bytes) -> bytes:
    """An FSO alignment file with its SAREF namespaces corrected (NAMESPACE_FIXES)."""
    for wrong, right in NAMESPACE_FIXES.items():
        alignment = alignment.replace(wrong, right)
    return alignment


def _subsets() -> list[ox.Triple]:
    return [t for path in sorted(ontologies_dir().glob("*-subset.ttl")) for t in _triples(path.read_bytes())]


def _declared(triples) -> set[str]:
    return {t.subject.value for t in triples if isinstance(t.subject, ox.NamedNode)}


@needs_shared
def test_every_subset_term_is_in_the_current_release_or_listed_as_v3_only():
    subset_terms = {iri for iri in _declared(_subsets()) if iri.startswith(OFFICIAL_NAMESPACES)}
    v4, v3 = _declared(_official(V4_FILES)), _declared(_official(V3_FILES))
    assert sorted(subset_terms - v4 - V3_ONLY) == []
    assert sorted(V3_ONLY - v3) == [] and sorted(V3_ONLY & v4) == []  # the list stays honest
    assert V3_ONLY <= subset_terms


@needs_shared
def test_every_subclass_axiom_of_the_subsets_follows_from_the_official_files():
    official = _official(V3_FILES + V4_FILES)
    for name in ALIGNMENT_FILES:
        official += _triples(_fixed((SHARED / name).read_bytes()))
    parents = defaultdict(set)
    for t in official:
        if t.predicate in (RDFS.subClassOf, RDFS.subPropertyOf) and isinstance(t.object, ox.NamedNode):
            parents[t.subject.value].add(t.object.value)

    def entailed(child: str, ancestor: str) -> bool:
        seen, todo = set(), [child]
        while todo:
            node = todo.pop()
            if node == ancestor:
                return True
            if node not in seen:
                seen.add(node)
                todo += parents[node]
        return False

    stated = {(t.subject.value, t.predicate.value, t.object.value) for t in official if isinstance(t.object, ox.NamedNode)}
    checked = 0
    for t in _subsets():
        if t.predicate in (RDFS.subClassOf, RDFS.subPropertyOf):
            assert entailed(t.subject.value, t.object.value), f"{t} is not in the official hierarchy"
            checked += 1
        elif t.predicate == OWL.inverseOf:
            assert (t.subject.value, t.predicate.value, t.object.value) in stated or \
                (t.object.value, t.predicate.value, t.subject.value) in stated, f"{t} is not an official inverse"
        elif t.predicate == RDF.type and t.object.value.startswith(OFFICIAL_NAMESPACES + (str(OWL),)):
            assert (t.subject.value, t.predicate.value, t.object.value) in stated, f"{t} is not stated officially"
    assert checked > 40


def test_the_fso_alignment_uses_the_official_saref_namespaces():
    text = (ontologies_dir() / "fso-subset.ttl").read_text(encoding="utf-8")
    assert "saref4bldg#" not in text and "saref4syst#" not in text
    assert ox.Triple(ox.NamedNode("https://saref.etsi.org/saref4bldg/FlowMovingDevice"), RDFS.subClassOf,
                     ox.NamedNode("https://w3id.org/fso#FlowMovingDevice")) in _subsets()


def test_every_graphtwin_term_has_a_label_and_a_comment():
    triples = _triples((ontologies_dir() / "graphtwin.ttl").read_bytes())
    terms = {iri for iri in _declared(triples) if iri.startswith(str(GT))}
    labelled = {t.subject.value for t in triples if t.predicate == RDFS.label}
    commented = {t.subject.value for t in triples if t.predicate == RDFS.comment}
    assert len(terms) > 100
    assert sorted(terms - labelled) == [] and sorted(terms - commented) == []
    versions = [t.object.value for t in triples if t.predicate == OWL.versionInfo]
    assert len(versions) == 1 and re.fullmatch(r"\d+\.\d+\.\d+", versions[0])


_USE = re.compile(r"(?:\bGT\.|\bGT\[\"|\bgt:)([A-Za-z_][A-Za-z0-9_]*)")


def test_every_gt_term_the_project_uses_is_declared():
    declared = _declared(_triples((ontologies_dir() / "graphtwin.ttl").read_bytes()))
    home = project_home()
    files = [*home.glob("service/**/*.py"), *home.glob("service/**/*.ttl"), *home.glob("signatures/**/*.toml"),
             *home.glob("queries/**/*.rq")]
    methods = {name for name in dir(Namespace) if not name.startswith("_")}
    used = {}
    for path in files:
        for match in _USE.finditer(path.read_text(encoding="utf-8")):
            if match.group(1) not in methods:
                used.setdefault(str(GT) + match.group(1), path.relative_to(home))
    assert len(used) > 50
    assert {iri: str(path) for iri, path in used.items() if iri not in declared} == {}


@needs_shared
def test_no_official_term_outside_the_subsets_is_taken_for_a_misspelling_of_one_inside():
    """The misspelling check (service.graph.vocabulary) sees only the subsets: an official SAREF,
    SAREF4BLDG, SAREF4SYST, FSO or Brick class, property or other term the subsets leave out must not
    be close enough to a subset term of its kind to be called its misspelling."""
    from service.graph.vocabulary import DeclaredTerms, closest_declared

    alignments = [t for name in ALIGNMENT_FILES for t in _triples(_fixed((SHARED / name).read_bytes()))]
    official = DeclaredTerms.from_triples(_official(V3_FILES + V4_FILES) + alignments)
    ours = DeclaredTerms.from_triples(_subsets())
    taken = {}
    for kind in ("classes", "properties", "values"):
        loaded, all_of_kind = getattr(ours, kind), getattr(official, kind)
        left_out = sorted(namespace + name for namespace, names in all_of_kind.items()
                          for name in set(names) - set(loaded.get(namespace, [])))
        assert len(left_out) > 20, kind
        taken |= {(kind, iri): closest_declared(iri, loaded) for iri in left_out}
    assert {key: meant for key, meant in taken.items() if meant} == {}
