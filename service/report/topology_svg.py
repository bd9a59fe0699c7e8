"""The flow topology as an SVG diagram: nodes in columns along the flow (left to right, loops cut at
their back edges), fluid edges solid, heat edges dashed, loop edges curved back underneath, a sensor
off the flow path below the node it observes; suspects, failing and matching sensors marked. The key
(``TOPOLOGY_KEY``) is the page's text, not the image's."""

from __future__ import annotations

import html
from collections import defaultdict
from collections.abc import Mapping

import numpy as np

from service.diagnosis.localization import FlowTopology
from service.graph.namespaces import local_name

__all__ = ["topology_svg", "TOPOLOGY_KEY"]

#: Layout in px: width of a label character, label line height, box height, row pitch, gap between
#: columns, margin; and label characters per line.
_CHAR_PX, _LINE_PX, _BOX_H, _ROW_PX, _GAP_PX, _MARGIN, _LABEL_CHARS = 6.7, 13, 34, 50, 40, 16, 20


#: Colours shared by the drawing and its key: suspect fill, failing red, matching green, component
#: fill, box border, edge grey, heat orange.
_SUSPECT, _RED, _GREEN, _FILL = "#f8c9c4", "#b3261e", "#2e7d32", "#eef2f8"
_BORDER, _EDGE, _HEAT = "#6b7a90", "#7d8797", "#d9822b"
#: The diagram's key, (CSS of a swatch, meaning), shown as HTML beside the image (:mod:`service.report.page`):
#: text inside an image shrinks with it, the page's text does not.
TOPOLOGY_KEY = (
    (f"background:{_SUSPECT};border:2.5px solid {_RED}",
     "suspect (between the last matching and the first failing sensor)"),
    (f"background:#fff;border:3px solid {_RED};border-radius:8px", "failing sensor"),
    (f"background:#fff;border:3px solid {_GREEN};border-radius:8px", "matching sensor"),
    (f"background:{_FILL};border:1.2px solid {_BORDER}", "component"),
    (f"background:#fff;border:1.2px solid {_BORDER};border-radius:8px", "sensor"),
    (f"background:#fff;border:2px dashed {_BORDER};border-radius:8px", "input sensor (fed to the model, not compared)"),
    (f"border-top:2px solid {_EDGE};height:0", "fluid flow"),
    (f"border-top:2px dashed {_HEAT};height:0", "heat transfer"),
    (f"border-top:2px dotted {_EDGE};height:0", "observes"),
)


def _layers(nodes: list[str], downstream: Mapping[str, set[str]]) -> tuple[dict[str, int], set[tuple[str, str]]]:
    """Layer of each node (longest path from a source after cutting the loops' back edges, found by
    depth-first search from the sources in name order) and the back edges."""
    state: dict[str, int] = {}
    back: set[tuple[str, str]] = set()

    def visit(node: str) -> None:
        state[node] = 1
        for nxt in sorted(downstream.get(node, ())):
            if state.get(nxt) == 1:
                back.add((node, nxt))
            elif nxt not in state:
                visit(nxt)
        state[node] = 2

    has_upstream = {m for n in nodes for m in downstream.get(n, ())}
    for node in [n for n in nodes if n not in has_upstream] + nodes:
        if node not in state:
            visit(node)
    layer = {n: 0 for n in nodes}
    for _ in nodes:  # longest path by relaxation; the graph without back edges is acyclic
        changed = False
        for n in nodes:
            for m in downstream.get(n, ()):
                if (n, m) not in back and layer[m] < layer[n] + 1:
                    layer[m], changed = layer[n] + 1, True
        if not changed:
            break
    return layer, back


def _label_lines(iri: str, width: int = _LABEL_CHARS) -> list[str]:
    """The node's local name, wrapped at underscores into lines of at most ``width`` characters."""
    lines: list[str] = []
    for word in local_name(iri).split("_"):
        if lines and len(lines[-1]) + 1 + len(word) <= width:
            lines[-1] += "_" + word
        else:
            lines.append(word)
    return lines


def topology_svg(
    topology: FlowTopology, sensors: set[str], *, suspects: set[str] = frozenset(),
    failing: set[str] = frozenset(), matching: set[str] = frozenset(), heat_edges: set[tuple[str, str]] = frozenset(),
    inputs: set[str] = frozenset(),
) -> str:
    """The flow topology as an SVG document: nodes in columns along the flow (left to right), fluid
    edges solid, heat edges dashed, loop edges curved back underneath; a sensor off the flow path sits
    below the node it observes, joined by a dotted line. Suspects are drawn red, failing sensors with
    a red border, matching sensors with a green one, the ``inputs`` (sensors the model takes as
    boundary inputs: never compared, neither matching nor failing) with a dashed one (``class``
    attributes ``suspect``, ``failing``, ``matching``, ``input`` and ``data-node`` say the same for
    machines)."""
    downstream, upstream = topology.physical_paths()  # a control loop's edges are the walks', not drawn
    flow_nodes = sorted(set(topology.downstream) | set(topology.upstream))
    layer, back = _layers(flow_nodes, downstream)
    off_path = sorted(sensors - set(flow_nodes))
    for sensor in off_path:
        layer[sensor] = layer.get(topology.place(sensor), 0)
    row: dict[str, int] = {}
    columns: dict[int, list[str]] = defaultdict(list)
    for index in sorted(set(layer.values())):
        taken: set[int] = set()

        def put(node: str, want: int) -> None:
            while want in taken:
                want += 1
            taken.add(want)
            row[node] = want
            columns[index].append(node)

        in_path = [n for n in flow_nodes if layer[n] == index]
        wants = {n: [row[u] for u in upstream.get(n, ()) if u in row] for n in in_path}
        for n in sorted(in_path, key=lambda n: (float(np.mean(wants[n])) if wants[n] else 0.0, n)):
            put(n, int(round(float(np.mean(wants[n])))) if wants[n] else 0)
        for sensor in (s for s in off_path if layer[s] == index):
            owner = topology.place(sensor)
            put(sensor, row[owner] + 1 if owner in row else 0)
    lines = {n: _label_lines(n) for n in layer}
    widths = {i: max(len(line) for n in members for line in lines[n]) * _CHAR_PX + 16 for i, members in columns.items()}
    left, x = {}, _MARGIN
    for i in sorted(columns):
        left[i] = x
        x += widths[i] + _GAP_PX
    width = x - _GAP_PX + _MARGIN
    box = {n: (left[layer[n]], _MARGIN + row[n] * _ROW_PX, widths[layer[n]]) for n in layer}
    height = _MARGIN + (max(row.values(), default=0) + 1) * _ROW_PX + 24  # room for a loop curving under the last row

    def anchor(n: str, side: str) -> tuple[float, float]:
        x, y, w = box[n]
        if side in ("top", "bottom"):
            return x + w / 2, y + (_BOX_H if side == "bottom" else 0)
        return (x + w if side == "right" else x), y + _BOX_H / 2

    parts = []
    for source in flow_nodes:
        for target in sorted(downstream.get(source, ())):
            if (target, source) in heat_edges:  # the localisation's reverse of a heat coupling: drawn once, as stated
                continue
            kind = "heat" if (source, target) in heat_edges else "fluid"
            if (source, target) in back or layer[target] <= layer[source]:
                (x1, y1), (x2, y2) = anchor(source, "bottom"), anchor(target, "bottom")
                dip = max(y1, y2) + _ROW_PX * 0.7
                d = f"M{x1:.0f},{y1:.0f} C{x1:.0f},{dip:.0f} {x2:.0f},{dip:.0f} {x2:.0f},{y2 + 4:.0f}"
            else:
                (x1, y1), (x2, y2) = anchor(source, "right"), anchor(target, "left")
                bend = _GAP_PX / 2
                d = f"M{x1:.0f},{y1:.0f} C{x1 + bend:.0f},{y1:.0f} {x2 - bend:.0f},{y2:.0f} {x2 - 4:.0f},{y2:.0f}"
            parts.append(f'<path class="edge {kind}" d="{d}" marker-end="url(#arrow)"/>')
    for sensor in off_path:
        owner = topology.place(sensor)
        if owner not in box or owner == sensor:
            continue
        if row[sensor] == row[owner] + 1:  # right below: a short vertical line
            (x1, y1), (x2, y2) = anchor(owner, "bottom"), anchor(sensor, "top")
            d = f"M{x1:.0f},{y1:.0f} L{x2:.0f},{y2:.0f}"
        else:  # further down: around the boxes in between, through the gap on the right
            (x1, y1), (x2, y2) = anchor(owner, "right"), anchor(sensor, "right")
            d = f"M{x1:.0f},{y1:.0f} H{x1 + _GAP_PX / 4:.0f} V{y2:.0f} H{x2:.0f}"
        parts.append(f'<path class="edge observes" d="{d}"/>')
    for n in sorted(box):
        x, y, w = box[n]
        classes = ["node", "sensor" if n in sensors else "component"]
        marks = (("suspect", suspects), ("failing", failing), ("matching", matching - inputs), ("input", inputs))
        classes += [mark for mark, members in marks if n in members]
        first = y + _BOX_H / 2 + 4 - (len(lines[n]) - 1) * _LINE_PX / 2
        text = "".join(f'<tspan x="{x + w / 2:.0f}" y="{first + k * _LINE_PX:.0f}">{html.escape(line)}</tspan>'
                       for k, line in enumerate(lines[n]))
        parts.append(
            f'<g class="{" ".join(classes)}" data-node="{html.escape(local_name(n))}"><title>{html.escape(n)}</title>'
            f'<rect x="{x:.0f}" y="{y:.0f}" width="{w:.0f}" height="{_BOX_H}" rx="{12 if n in sensors else 3}"/>'
            f'<text>{text}</text></g>')
    style = ("text{font:11px DejaVu Sans Mono,monospace;text-anchor:middle;fill:#222}"
             f".node rect{{fill:{_FILL};stroke:{_BORDER};stroke-width:1.2}}.sensor rect{{fill:#fff}}"
             f".suspect rect{{fill:{_SUSPECT};stroke:{_RED};stroke-width:2.5}}"
             f".failing rect{{stroke:{_RED};stroke-width:3}}"
             f".matching rect{{stroke:{_GREEN};stroke-width:3}}.input rect{{stroke-width:2;stroke-dasharray:5 3}}"
             f".edge{{fill:none;stroke:{_EDGE};stroke-width:1.4}}.heat{{stroke:{_HEAT};stroke-dasharray:6 3}}"
             ".observes{stroke-dasharray:2 3}")
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0f}" height="{height:.0f}" '
            f'viewBox="0 0 {width:.0f} {height:.0f}"><style>{style}</style><defs><marker id="arrow" viewBox="0 0 8 8" '
            f'refX="7" refY="4" markerWidth="7" markerHeight="7" orient="auto"><path d="M0,0 L8,4 L0,8 z" '
            f'fill="{_EDGE}"/></marker></defs>{"".join(parts)}</svg>')
