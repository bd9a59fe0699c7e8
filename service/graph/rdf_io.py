"""RDF in: the format of a file name, suffix or media type, a complete parse of a document, and a
SPARQL syntax error a user can act on.

Turtle, N-Triples, RDF/XML and JSON-LD, parsed by pyoxigraph. A document is parsed completely before
anything is written, or :class:`~service.errors.ModelLoadError` names the source, line and column.
A leading UTF-8 byte-order mark is skipped; an IRI that JSON-LD would drop silently (relative,
invalid) is an error there as in the other formats. See ``docs/graph-store.md``.
"""

from __future__ import annotations

import re
from xml.parsers import expat

import pyoxigraph as ox

from service.errors import ModelLoadError, UnsupportedFormatError
from service.graph.namespaces import PREFIXES

__all__ = ["rdf_format", "parse_rdf", "sparql_syntax_message", "first_use"]

#: What pyoxigraph's syntax error messages start with (the position, given as ``lineno``/``offset``
#: too): ``Parser error at line 3 between columns 16 and 20: ``, ``… at line 2 column 11: ``,
#: ``… between line 2 column 11 and line 5 column 1: ``.
_POSITION_PREFIX = re.compile(r"^Parser error (at|between) line [^:]*: ")
#: A Turtle comment: ``#`` at a line's start or after white space (not inside an IRI) to the line's end.
_COMMENT = re.compile(r"(^|\s)#.*$")
_BOM = b"\xef\xbb\xbf"
#: pyoxigraph's SPARQL syntax errors: ``error at 1:31: expected one of Prefix not found, ['%'], …``.
_SPARQL_POSITION = re.compile(r"^error at (\d+):(\d+): (.*)$", re.DOTALL)

_SUFFIXES = {
    "ttl": ox.RdfFormat.TURTLE, "turtle": ox.RdfFormat.TURTLE, "nt": ox.RdfFormat.N_TRIPLES,
    "ntriples": ox.RdfFormat.N_TRIPLES, "n-triples": ox.RdfFormat.N_TRIPLES, "rdf": ox.RdfFormat.RDF_XML,
    "xml": ox.RdfFormat.RDF_XML, "owl": ox.RdfFormat.RDF_XML, "rdfxml": ox.RdfFormat.RDF_XML,
    "rdf/xml": ox.RdfFormat.RDF_XML, "jsonld": ox.RdfFormat.JSON_LD, "json-ld": ox.RdfFormat.JSON_LD,
    "json": ox.RdfFormat.JSON_LD,
}


def rdf_format(name_or_suffix: str) -> ox.RdfFormat:
    """``"ttl"``, ``".jsonld"``, ``"rdf/xml"``, ``"text/turtle"``… → the pyoxigraph format.

    :raises UnsupportedFormatError: (a ``ValueError``) for an unsupported format, listing the supported ones.
    """
    key = name_or_suffix.lower().lstrip(".").split(";")[0].strip()
    if key in _SUFFIXES:
        return _SUFFIXES[key]
    by_media = ox.RdfFormat.from_media_type(key)
    if by_media in (ox.RdfFormat.TURTLE, ox.RdfFormat.N_TRIPLES, ox.RdfFormat.RDF_XML, ox.RdfFormat.JSON_LD):
        return by_media
    raise UnsupportedFormatError(
        f"unsupported RDF format {name_or_suffix!r}: use Turtle (.ttl), N-Triples (.nt), RDF/XML (.rdf) or JSON-LD (.jsonld)"
    )


def parse_rdf(data: bytes, fmt: ox.RdfFormat, source_name: str, base_iri: str | None = None) -> list[ox.Triple]:
    """Parse completely (nothing is written anywhere) or raise :class:`ModelLoadError`.

    A leading UTF-8 byte-order mark is skipped. RDF/XML must be well-formed XML (checked by expat
    first, which names the line and column; pyoxigraph reads a document cut short up to the cut).
    JSON-LD may not hold an IRI that is relative (without ``base_iri``) or invalid, nor an invalid
    language tag: where the JSON-LD algorithms drop the triple, this names it.
    """
    data = data.removeprefix(_BOM)
    if fmt == ox.RdfFormat.RDF_XML:
        _check_well_formed_xml(data, source_name)
    quads = _parsed(data, fmt, source_name, base_iri)
    if fmt == ox.RdfFormat.JSON_LD:
        lenient = _parsed(data, fmt, source_name, base_iri, lenient=True)
        if len(lenient) != len(quads):
            raise _dropped_by_json_ld(lenient, len(lenient) - len(quads), source_name)
    return [ox.Triple(q.subject, q.predicate, q.object) for q in quads]


def _parsed(data: bytes, fmt: ox.RdfFormat, source_name: str, base_iri: str | None, lenient: bool = False) -> list[ox.Quad]:
    """Every quad of ``data``, or :class:`ModelLoadError` (with pyoxigraph's position, named once)."""
    try:
        return list(ox.parse(data, format=fmt, base_iri=base_iri, lenient=lenient))
    except SyntaxError as exc:
        message = _POSITION_PREFIX.sub("", exc.msg or str(exc)) + _continued_statement_hint(data, fmt, exc.lineno)
        raise ModelLoadError(source_name, message, exc.lineno, exc.offset) from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise ModelLoadError(source_name, str(exc)) from None
    except MemoryError as exc:  # pyoxigraph's bound on one token or comment ("Reached the buffer maximal size")
        raise ModelLoadError(source_name, f"a token or comment too long to parse ({exc})") from None


def _continued_statement_hint(data: bytes, fmt: ox.RdfFormat, line: int | None) -> str:
    """For Turtle and TriG: where the last line with a statement before the error's line ends with
    ``;`` or ``,``, the parser read the error's line as more of that statement; a hint saying so."""
    if fmt not in (ox.RdfFormat.TURTLE, ox.RdfFormat.TRIG) or not line:
        return ""
    before = [_COMMENT.sub("", text).rstrip() for text in data.decode("utf-8", "replace").splitlines()[: line - 1]]
    last = next((text for text in reversed(before) if text), "")
    if not last.endswith((";", ",")):
        return ""
    number = len(before) - [bool(text) for text in reversed(before)].index(True)
    return (f" (line {number} ends with {last[-1]!r}, so the statement goes on here: if it was complete, end it "
            "with '.')")


def _check_well_formed_xml(data: bytes, source_name: str) -> None:
    """:raises ModelLoadError: ``data`` is not well-formed XML (line, column of the first error)."""
    try:
        expat.ParserCreate().Parse(data, True)
    except expat.ExpatError as exc:
        message = expat.ErrorString(exc.code)
        if exc.code == expat.errors.codes[expat.errors.XML_ERROR_NO_ELEMENTS]:
            message += " (the document has no root element, or ends before it is closed)"
        raise ModelLoadError(source_name, f"not well-formed XML: {message}", exc.lineno, exc.offset + 1) from None


def _dropped_by_json_ld(lenient: list[ox.Quad], dropped: int, source_name: str) -> ModelLoadError:
    """The error for a JSON-LD document whose strict parse dropped ``dropped`` triples its ``lenient``
    parse kept: it names the first triple with an invalid IRI or language tag."""
    for quad in lenient:
        for term in (quad.subject, quad.predicate, quad.object, quad.graph_name):
            try:
                if isinstance(term, ox.NamedNode):
                    ox.NamedNode(term.value)
                elif isinstance(term, ox.Literal) and term.language is not None:
                    ox.Literal(term.value, language=term.language)
            except ValueError as exc:
                triple = f"{quad.subject} {quad.predicate} {quad.object}"
                if isinstance(term, ox.NamedNode):
                    return ModelLoadError(source_name, (
                        f"invalid IRI {term.value!r} ({exc}) in the triple {triple}: an @id, @type, key or IRI "
                        "value the @context does not expand to an absolute IRI (JSON-LD would drop the triple)"))
                return ModelLoadError(source_name, (
                    f"invalid language tag {term.language!r} ({exc}) in the triple {triple} (JSON-LD would drop it)"))
    return ModelLoadError(source_name, f"JSON-LD would drop {dropped} triples holding an invalid term")


def sparql_syntax_message(query: str, error: SyntaxError) -> str:
    """A SPARQL syntax error as a user can act on it: line and column, the query's text there, and
    for a prefixed name whose prefix the query does not declare, the ``PREFIX`` line to add
    (graphtwin's usual prefixes named with their IRI) instead of the parser's character classes."""
    text = error.msg if isinstance(getattr(error, "msg", None), str) else str(error)
    found = _SPARQL_POSITION.match(text)
    if not found:
        return f"SPARQL syntax error: {text}"
    line, column, detail = int(found[1]), int(found[2]), found[3]
    lines = query.splitlines() or [""]
    source = lines[line - 1] if 0 < line <= len(lines) else ""
    where = f"line {line}, column {column}: {source.strip()!r}"
    if "Prefix not found" in detail:
        name = re.search(r"(?<![\w.:-])([A-Za-z][\w.-]*):[\w.%:-]*$", source[:column - 1])
        declared = set(re.findall(r"PREFIX\s+([\w.-]*):", query, flags=re.IGNORECASE))
        if name is None or name.group(1) in declared:
            return f"SPARQL syntax error at {where}: a prefixed name whose prefix the query does not declare"
        prefix = name.group(1)
        known = PREFIXES.get(prefix)
        add = f"add PREFIX {prefix}: <{known}>" if known else f"declare it with PREFIX {prefix}: <…>"
        return f"SPARQL syntax error at {where}: the prefix {prefix}: is not declared ({add})"
    expected = detail if len(detail) <= 120 else detail[:117].rsplit(",", 1)[0] + ", …"
    return f"SPARQL syntax error at {where}: {expected}"


#: A prefix declaration of Turtle, TriG or N3 (``@prefix``) or in SPARQL style (``PREFIX``).
_PREFIX_DECLARATION = re.compile(r"(?:@prefix|\bPREFIX)\s+([A-Za-z][\w.-]*)?:\s*<([^>]*)>", re.IGNORECASE)


def first_use(text: str, iri: str) -> tuple[int, int] | None:
    """Where the RDF source ``text`` first uses ``iri``, as (line, column), both from 1: written whole
    (``<iri>``, or quoted in RDF/XML and JSON-LD) or as a prefixed name whose prefix the text
    declares; None where it does not."""
    spellings = [re.escape(iri) + r"(?![\w/#-])"]
    for prefix, namespace in _PREFIX_DECLARATION.findall(text):
        if namespace and iri.startswith(namespace) and len(iri) > len(namespace):
            spellings.append(rf"(?<![\w:-]){re.escape(prefix)}:{re.escape(iri[len(namespace):])}(?![\w-])")
    found = re.search("|".join(spellings), text)
    if found is None:
        return None
    position = found.start()
    return text.count("\n", 0, position) + 1, position - text.rfind("\n", 0, position)
