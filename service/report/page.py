"""A run's report: one self-contained HTML page built from what the store holds about the run.

``report_html(store, run_id)`` reads the calibration run and the diagnosis based on it
(:mod:`service.report.stored_run`) and shows: per sensor the stored metrics and a figure of measured
against modelled with an interval (:mod:`service.report.run_series`); the flow-path localisation
drawn on the system topology (:mod:`service.report.topology_svg`); the operating regimes with the
test RMSE per sensor in each; the ranked missing effects with their evidence in words
(:func:`evidence_words`, the numbers in a ``<details>``); the test RMSE across the model's versions. Everything is in the page (base64 PNG or SVG data URIs, inline style, no
script) and ``CONTENT_SECURITY_POLICY`` lets the browser load nothing else. More: ``docs/report.md``.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from service.calibration.metrics import on_interval_scale
from service.diagnosis.error_history import error_history
from service.diagnosis.localization import FlowTopology
from service.diagnosis.report import fails_at
from service.diagnosis.separation import distance_text
from service.graph.namespaces import GTR, local_name
from service.graph.store import GraphStore
from service.graph.units import (
    difference_label,
    difference_text,
    difference_unit,
    logged_scale_text,
    quantity_text,
    unit_label,
)
from service.report.run_series import INTERVAL_LEVEL, INTERVAL_Z, RunSeries, recompute_series
from service.report.stored_run import StoredCandidate, StoredDiagnosis, StoredRun, read_diagnosis, read_run
from service.report.topology_svg import TOPOLOGY_KEY, topology_svg

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["report_html", "evidence_words", "p_value_text", "CONTENT_SECURITY_POLICY", "SOME_EVIDENCE_DELTA_BIC"]

#: Only inline styles and ``data:`` images: the browser refuses anything else (no request leaves the page).
CONTENT_SECURITY_POLICY = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
#: ΔBIC below which a candidate that removes some test-window error has "some evidence" ("positive"
#: on Kass & Raftery's scale); "clear evidence" is the diagnosis's significance (``docs/report.md``).
SOME_EVIDENCE_DELTA_BIC = -2.0
#: p-values below this print as "< 10⁻⁶": smaller ones say nothing more to an engineer.
SMALLEST_P_SHOWN = 1e-6


def _img(data: bytes, media_type: str, alt: str, css_class: str) -> str:
    encoded = base64.b64encode(data).decode("ascii")
    return f'<img class="{css_class}" alt="{html.escape(alt)}" src="data:{media_type};base64,{encoded}">'


def _png(fig: Figure) -> bytes:
    """The figure as PNG bytes (closed)."""
    from service.report.plots import save_figure

    buffer = io.BytesIO()
    save_figure(fig, buffer)
    return buffer.getvalue()


def _number(value: float, digits: int = 3) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.{digits}g}"


def _breakable(name: str) -> str:
    """A node's local name, escaped, free to wrap after each underscore (``<wbr>``): a long sensor
    name as a column header no longer widens its table past the page."""
    return "_<wbr>".join(html.escape(part) for part in local_name(name).split("_"))


def p_value_text(p: float) -> str:
    """A p-value for people: two significant digits, ``< 10⁻⁶`` below :data:`SMALLEST_P_SHOWN`."""
    if p is None or not np.isfinite(p):
        return "–"
    return "< 10⁻⁶" if p < SMALLEST_P_SHOWN else f"{p:.2g}"


def evidence_words(candidate: StoredCandidate) -> str:
    """The diagnosis's numbers in words: ``clear evidence`` (significant: ΔBIC < −10 and ≥ 20 % of
    the evaluation half's error removed), ``some evidence`` (ΔBIC < :data:`SOME_EVIDENCE_DELTA_BIC`
    and some of that error removed), else ``no evidence``."""
    if candidate.significant:
        return "clear evidence"
    if candidate.delta_bic < SOME_EVIDENCE_DELTA_BIC and candidate.test_improvement > 0:
        return "some evidence"
    return "no evidence"


def _table(header: list[str], rows: list[list[str]], css_class: str = "", rule_column: int | None = None) -> str:
    """An HTML table; ``header`` and ``rows`` are HTML already. The ``rule_column``'s cells get class
    ``rule`` (a regime's rule, wrapped at its conditions)."""
    head = "".join(f"<th>{h}</th>" for h in header)
    body = "".join("<tr>" + "".join(f'<td class="rule">{cell}</td>' if j == rule_column else f"<td>{cell}</td>"
                                    for j, cell in enumerate(r)) + "</tr>" for r in rows)
    return f'<table class="{css_class}"><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _rule(rule: str) -> str:
    """A regime's rule, escaped, each ``or`` on a line of its own (the rules are or-ed conditions)."""
    return html.escape(rule).replace(" or ", "<br>or ")


def _discrepancy_section(run: StoredRun) -> str:
    """A Bayesian run's discrepancy GP per sensor (posterior medians): how much misfit it took, how slowly
    it varies."""
    if not run.discrepancy:
        return ""
    names = list(dict.fromkeys(name for entries in run.discrepancy.values() for name in entries))
    rows = [[_breakable(sensor)] + [html.escape(quantity_text(*entries[name])) if name in entries else "–"
                                    for name in names] for sensor, entries in sorted(run.discrepancy.items())]
    header = ["sensor"] + [html.escape(name.replace("length_scale:", "length scale over ")) for name in names]
    return ("<h3>The discrepancy, per sensor</h3><p>The Gaussian process of the Kennedy–O'Hagan model: its "
            "amplitude σ_f (what the model misses, beyond noise), its noise σ_n and its length scales, posterior "
            "medians.</p>" + _table(header, rows, "discrepancy"))


def _run_notes(run: StoredRun) -> str:
    """A banner over a posterior whose sampler did not converge, and what the run noticed (its warnings)."""
    out = []
    if run.sampler and not run.sampler.converged:
        out.append('<p class="bad">The sampler did not converge: the chain stopped at its step limit before it was '
                   '20 integrated autocorrelation times long, so the estimates, intervals and bands below are not '
                   'to be trusted. Run it again with more steps, or fewer discrepancy inputs.</p>')
    if run.warnings:
        out.append("<p>What the run noticed:</p><ul>" + "".join(f"<li>{html.escape(w)}</li>" for w in run.warnings)
                   + "</ul>")
    return "".join(out)


def _sensor_section(run: StoredRun, diagnosis: StoredDiagnosis | None, series: RunSeries | None,
                    series_note: str) -> str:
    from service.report.plots import measured_vs_model_figure

    failing = diagnosis.failing_sensors if diagnosis else set()
    rows = []
    for sensor in sorted(set(run.units)):
        test = run.metrics.get("test", {}).get(sensor, {})
        train = run.metrics.get("train", {}).get(sensor, {})
        verdict = ('<span class="bad">yes</span>' if sensor in failing else "no") if diagnosis else "–"
        ratios = ([None, None] if on_interval_scale(run.units[sensor])  # a mean in °C depends on the zero
                  else [test.get("cv_rmse_percent"), test.get("nmbe_percent")])
        noise, rmse = test.get("noise"), test.get("rmse")
        over_noise = rmse / noise if noise and rmse is not None else None  # runs stored before have no noise
        logged = logged_scale_text(run.units[sensor], series.logged_units.get(sensor, "")) if series else None
        unit = difference_label(run.units[sensor]) + (f" (as logged: {logged})" if logged else "")
        rows.append([_breakable(sensor), _number(train.get("rmse")), _number(rmse), _number(noise),
                     _number(over_noise), _number(test.get("mae")), _number(test.get("r2")), *map(_number, ratios),
                     html.escape(unit), verdict])
    out = ["<h2>Measured against the model, per sensor</h2>",
           _table(["sensor", "train RMSE", "test RMSE", "test noise σ", "test RMSE / σ", "test MAE", "test R²",
                   "CV(RMSE) %", "NMBE %", "unit", "located failure"], rows, "metrics")]
    if diagnosis:
        out.append("<p>Located failure: the diagnosis located a failure at this sensor (a sensor that only inherits "
                   "a failure from upstream is not located again).</p>")
    if series is None:
        out.append(f'<p class="note">No measured-vs-model figures: {html.escape(series_note)}</p>')
        return "".join(out)
    if series.posterior_band:
        model_name, band_name = "model at the posterior median θ", "posterior predictive 5–95 %"
        out.append(f"<p>{series.window.capitalize()} window. The model is simulated at the posterior median "
                   "parameters; the band is the run's posterior predictive 5–95 % interval (the model at posterior "
                   "draws + the discrepancy Gaussian process + measurement noise), stored with the run.</p>")
    else:
        model_name, band_name = "model", f"ŷ ± {INTERVAL_Z:.3f}·s (training RMSE s)"
        out.append(f'<p>{series.window.capitalize()} window. The model is simulated at the stored estimates; the band '
                   f'is the {100 * INTERVAL_LEVEL:.0f} % prediction interval '
                   f'ŷ ± {INTERVAL_Z:.3f}·s with s the sensor\'s training RMSE.</p>')
    out += [f'<p class="note">{html.escape(note)}</p>' for note in series.notes]
    left_out = None if series.compared is None or series.compared.all() else ~series.compared
    if left_out is not None:
        out.append(f"<p>Shaded grey: the {int(left_out.sum())} of {left_out.size} steps the run's operating filter "
                   f"({html.escape(' and '.join(run.settings.get('only_when', [])))}) left out of its fit and "
                   "metrics.</p>")
    for sensor in series.predicted:
        rmse = difference_text(series.rmse[sensor], series.units[sensor], series.logged_units.get(sensor, ""))
        picture = _png(measured_vs_model_figure(
            series.timestamps, {sensor: series.observed[sensor]}, {model_name: {sensor: series.predicted[sensor]}},
            series.units, {sensor: series.band[sensor]}, title=f"{local_name(sensor)}: {series.window} window, RMSE {rmse}",
            interval_label=band_name, left_out=left_out))
        alt = f"measured vs model: {local_name(sensor)}, {series.window} window, RMSE {rmse}"
        out.append(f'<figure>{_img(picture, "image/png", alt, "series")}</figure>')
    return "".join(out)


def _matching_sensors(run: StoredRun, diagnosis: StoredDiagnosis | None) -> set[str]:
    """The compared sensors within the failure ratio of their noise on the test window (from the
    stored metrics; a run stored without its noise has only those a failure location names)."""
    if diagnosis is None:
        return set()
    within = {sensor for sensor, m in run.metrics.get("test", {}).items()
              if m.get("noise", 0.0) > 0.0 and not fails_at(m.get("rmse", np.inf), m["noise"])}
    return (within | diagnosis.matching_sensors) - diagnosis.failing_sensors


def _topology_section(store: GraphStore, run: StoredRun, diagnosis: StoredDiagnosis | None) -> str:
    out = ["<h2>Where along the flow path the model fails</h2>"]
    if not store.has_model(run.model):
        return out[0] + f'<p class="note">Model {html.escape(run.model)} is no longer in the store: no topology.</p>'
    topology = FlowTopology.from_store(store, run.model)
    heat = {(r["from"].value, r["to"].value) for r in store.run_named_query("flow-edges", dataset=run.model)
            if r["kind"].value == "heat"}
    inputs = _boundary_nodes(store, run.model)
    svg = topology_svg(topology, set(run.units) | inputs,
                       suspects=diagnosis.suspects if diagnosis else set(),
                       failing=diagnosis.failing_sensors if diagnosis else set(),
                       matching=_matching_sensors(run, diagnosis), heat_edges=heat, inputs=inputs)
    key = "".join(f'<li><span class="swatch" style="{style}"></span>{html.escape(meaning)}</li>'
                  for style, meaning in TOPOLOGY_KEY)
    out.append(f'<figure>{_img(svg.encode("utf-8"), "image/svg+xml", f"flow topology of {run.model}", "topology")}'
               f'<figcaption><ul class="key">{key}</ul></figcaption></figure>')
    if diagnosis is None:
        out.append('<p class="note">No diagnosis is based on this run: nothing is located.</p>')
    elif not diagnosis.locations:
        out.append("<p>The diagnosis located no failure: the model matches every sensor within its noise.</p>")
    else:
        items = "".join(
            f'<li>{html.escape(loc.text)} <span class="suspects">Suspects: '
            f'{html.escape(", ".join(local_name(c) for c in loc.components) or "none")}</span></li>'
            for loc in diagnosis.locations)
        out.append(f'<ul class="locations">{items}</ul>')
    return "".join(out)


def _boundary_nodes(store: GraphStore, model: str) -> set[str]:
    """Building nodes of the measuring devices the assembly made boundary inputs."""
    return {r["node"].value for r in store.run_named_query("assembled-components", model=model)
            if r["role"].value == "boundary input"}


def _regimes_section(run: StoredRun) -> str:
    out = "<h2>Operating regimes</h2>"
    if not run.regimes:
        return out + '<p class="note">The run has no test window, so no error per regime.</p>'
    sensors = [s for s in run.metrics.get("test", {}) if any(s in r["rmse"] for r in run.regimes)]
    rows = [[html.escape(r["regime"]), _rule(r["rule"]), f"{100 * r['share']:.0f} %"]
            + [html.escape(quantity_text(r["rmse"][s], difference_unit(run.units.get(s, ""))))
               if s in r["rmse"] else "–"
               for s in sensors]
            for r in run.regimes]
    header = ["regime", "rule", "share of the test window"] + [f"RMSE {_breakable(s)}" for s in sensors]
    return (out + "<p>Clusters of the boundary inputs (mini-batch k-means), each described by the rule of a "
            "shallow decision tree, and the test RMSE of every sensor in each: where the model fails.</p>"
            + _table(header, rows, "regimes", rule_column=1))


def _estimates_section(run: StoredRun) -> str:
    """The run's parameter estimates: median and 16–84 % interval (the point fit's ±1 standard error,
    the posterior's quantiles), unit, and whether the data identified the parameter (and why not)."""
    rows = [[_breakable(e.node), _breakable(e.name), _number(e.median, 4)
             + (f' <span class="bad">at its {e.at_bound} bound</span>' if e.at_bound else ""),
             f"{_number(e.quantile16, 4)} – {_number(e.quantile84, 4)}", f"{_number(e.lower, 4)} – {_number(e.upper, 4)}",
             html.escape(unit_label(e.unit)),
             "yes" if e.identified else '<span class="bad">no</span>' + (f": {html.escape(e.reasons)}" if e.reasons else "")]
            for e in run.estimates.values()]
    return ("<h2>Parameter estimates</h2>"
            + _table(["node", "parameter", "estimate", "16–84 %", "bounds", "unit", "identified"], rows, "estimates"))


def _numbers(candidate: StoredCandidate) -> str:
    """The statistics behind the words, one click away (``<details>``: no script needed)."""
    facts = [("ΔBIC", _number(candidate.delta_bic, 4)), ("score statistic S", _number(candidate.score)),
             ("p-value of S", p_value_text(candidate.p_value)),
             ("significant", "yes" if candidate.significant else "no")]
    rows = "".join(f"<dt>{name}</dt><dd>{html.escape(value)}</dd>" for name, value in facts)
    return f"<details><summary>numbers</summary><dl>{rows}</dl></details>"


def _lookalike_note(candidate) -> str:
    """For a candidate the data cannot tell from the answer: that, and what would separate them; for
    one they tell apart: how far its errors lie from the answer's."""
    fit_z, held_out_z = (z if np.isfinite(z) else None for z in (candidate.fit_z, candidate.held_out_z))
    if fit_z is not None or held_out_z is not None:
        sentence = distance_text(fit_z, held_out_z)
        return f'<p class="lookalike"><b>Told apart from the answer:</b> {html.escape(sentence)}.</p>'
    if not candidate.indistinguishable:
        return ""
    items = "".join(f"<li>{html.escape(text)}</li>" for text in candidate.would_separate)
    return ('<p class="lookalike"><b>Indistinguishable from the answer on these data.</b> What would separate '
            f"them:</p><ul>{items}</ul>")


def _diagnosis_sections(diagnosis: StoredDiagnosis | None) -> str:
    if diagnosis is None:
        return "<h2>Which effect is missing</h2><p class=\"note\">No diagnosis is based on this run.</p>"
    if not diagnosis.effects:
        return ("<h2>Which effect is missing</h2><p class=\"note\">The effect catalog was not tested on this run "
                "(<code>graphtwin compare</code> locates the failures only; <code>graphtwin diagnose</code> tests the "
                "catalog).</p>")
    words = {"clear evidence": "good", "some evidence": "some", "no evidence": "none"}
    effects = _table(
        ["rank", "effect", "at", "evidence", "test error removed", "statistics", "what it explains"],
        [[str(e.rank), f'<span class="effect">{html.escape(e.effect)}</span><br>'
                       f'<small>{html.escape(e.label)}</small>',
          _breakable(e.node), f'<span class="{words[evidence_words(e)]}">{evidence_words(e)}</span>',
          f"{100 * e.test_improvement:.0f} %" if np.isfinite(e.test_improvement) else "–", _numbers(e),
          html.escape(e.explanation) + _lookalike_note(e)]
         for e in diagnosis.effects], "effects")
    reasons = "".join(f"<li>{html.escape(reason)}</li>" for reason in diagnosis.not_applicable)
    not_tried = f'<h3>Not tried</h3><ul class="not-tried">{reasons}</ul>' if reasons else ""
    return ("<h2>Which effect is missing (best first)</h2><p>Clear evidence: the diagnosis calls the effect "
            "significant (ΔBIC &lt; −10 and at least 20 % of the test-window error removed); some evidence: ΔBIC "
            f"&lt; {SOME_EVIDENCE_DELTA_BIC:g} and some of that error removed; else no evidence. The numbers are "
            f"under <i>numbers</i>.</p>{effects}{not_tried}")


def _history_section(store: GraphStore, run: StoredRun) -> str:
    from service.report.plots import error_history_figure

    history = error_history(store, run.model)
    versions, units = history.versions, history.units
    out = ["<h2>Error across model versions</h2>"]
    if not versions:
        return out[0] + '<p class="note">No calibration of this model with a test window is stored.</p>'

    def cells(values: list[float], sensor: str) -> list[str]:
        return [html.escape(quantity_text(v, units.get(sensor, ""))) for v in values]

    out.append('<p class="note">Each version\'s latest calibration with a test window (this run\'s numbers are in the '
               'tables above where it is that calibration).</p>')
    if not history.comparable:
        out.append('<p class="note bad">The versions were tested on different data, windows or operating filters: '
                   'their errors differ by that as much as by the model.</p>')
    rows = [[_breakable(s)] + cells(values, s) for s, values in history.rmse.items()]
    rows.append(["tested on"] + [html.escape(t) for t in history.tested_on])
    out.append(_table(["sensor"] + [_breakable(v) for v in versions], rows, "history"))
    if history.regime_rmse:
        numbers = {r["rule"]: html.escape(str(r["regime"])) for r in run.regimes}  # this run's, as above
        rows = [[numbers.get(rule, "–"), _rule(rule), _breakable(s)] + cells(values, s)
                for rule, sensors in history.regime_rmse.items() for s, values in sensors.items()]
        out.append(_table(["regime", "rule", "sensor"] + [_breakable(v) for v in versions], rows, "history-regimes",
                          rule_column=1))
    picture = _png(error_history_figure(history))
    out.append(f'<figure>{_img(picture, "image/png", f"test RMSE across versions of {run.model}", "history")}</figure>')
    return "".join(out)


_STYLE = """body{font:14px/1.45 system-ui,sans-serif;margin:24px auto;max-width:1240px;color:#1d232b;padding:0 16px}
h1{font-size:22px;overflow-wrap:anywhere}h2{font-size:17px;margin-top:30px;border-bottom:1px solid #d5dae1;
padding-bottom:4px}table{border-collapse:collapse;margin:8px 0;font-size:13px;max-width:100%}th,td{border:1px solid
#d5dae1;padding:3px 7px;vertical-align:top;text-align:left}th{background:#f1f4f8}td.rule{min-width:22ch;
max-width:46ch}table.estimates td:last-child{max-width:46ch;overflow-wrap:anywhere}
.note{color:#8a4b00;background:#fff6e5;padding:6px 10px}figure{margin:10px 0}img{max-width:100%}
.bad{color:#b3261e;font-weight:600}.good{color:#2e7d32;font-weight:600}.some{color:#8a4b00;font-weight:600}
.none{color:#5a6472}.summary{font-weight:600;background:#eef6ee;padding:8px 12px}dl{display:grid;
grid-template-columns:max-content auto;gap:2px 14px}dt{color:#5a6472}dd{margin:0;overflow-wrap:anywhere}
details dl{margin:4px 0;font-size:12px}summary{color:#2f5d9a;cursor:pointer}ul.key{list-style:none;padding:0;
margin:6px 0;font-size:13px;display:flex;flex-wrap:wrap;gap:4px 18px}.swatch{display:inline-block;width:22px;
height:12px;margin-right:6px;vertical-align:middle;box-sizing:border-box}"""


def _start_text(start_from: dict) -> str:
    """A run's ``start_from`` setting (:func:`service.calibration.run.calibrated_start`) in words."""
    runs = ", ".join(run.rsplit("/", 1)[-1] for run in start_from["runs"])
    return f"the latest calibration of {start_from['model']} (run {runs})"


def report_html(store: GraphStore, run_id: str, *, locate_data: Callable[[str], Path] | None = None) -> str:
    """The report page of run ``run_id`` (a calibration run, or a diagnosis graph ``<run>-diagnosis``).

    :param locate_data: the run's recorded data source (``gt:dataSource``) → the file's path; raises
        KeyError or FileNotFoundError when it is not available. Without it, or when it raises, the
        page shows the stored numbers without the measured-vs-model figures and says why.
    :raises NotFoundError: no such run in the store.
    """
    run = read_run(store, run_id)
    diagnosis = read_diagnosis(store, run.run_id)
    series, series_note = None, "no data locator was given"
    if locate_data is not None:
        try:
            series = recompute_series(store, run, locate_data(run.data_source))
        except (LookupError, FileNotFoundError, ValueError) as exc:
            series_note = str(exc.args[0]) if isinstance(exc, KeyError) else str(exc)
    windows = [("train", run.train)] + ([("test", run.test)] if run.test else [])
    facts = "".join(f"<dt>{html.escape(k)}</dt><dd>{html.escape(v)}</dd>" for k, v in [
        ("model", f"{run.model} (version {run.version})"), ("method", run.method), ("data", run.data_source),
        *[(f"{name} window", f"{start} – {end}") for name, (start, end) in windows],
        *([("compared only where", " and ".join(run.settings["only_when"]))] if run.settings.get("only_when") else []),
        *([("warm-up before each window", f"{run.settings['warmup_s'] / 3600:g} h")] if "warmup_s" in run.settings else []),
        *([("training window not scored over its first", f"{run.settings['unscored_start_s'] / 3600:g} h")]
          if "unscored_start_s" in run.settings else []),
        *([("started from", _start_text(run.settings["start_from"]))] if "start_from" in run.settings else []),
        *([("sampler", run.sampler.describe())] if run.sampler else []),
        ("finished", run.ended), ("run graph", store.run_graph(run.run_id).value),
        ("diagnosis", diagnosis.iri if diagnosis else "none"),
    ])
    summary = f'<p class="summary">{html.escape(diagnosis.summary)}</p>' if diagnosis and diagnosis.summary else ""
    generated = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    title = f"graphtwin report: {run.run_id}"
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<meta http-equiv=\"Content-Security-Policy\" content=\"{CONTENT_SECURITY_POLICY}\">"
        f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>{html.escape(title)}</title>"
        f"<style>{_STYLE}</style></head><body>"
        f"<h1>{html.escape(title)}</h1><dl class=\"facts\">{facts}</dl>{_run_notes(run)}{summary}"
        f"{_sensor_section(run, diagnosis, series, series_note)}{_estimates_section(run)}{_discrepancy_section(run)}"
        f"{_topology_section(store, run, diagnosis)}"
        f"{_regimes_section(run)}{_diagnosis_sections(diagnosis)}{_history_section(store, run)}"
        f"<p class=\"note\">Generated {generated} by graphtwin from the store's graphs ({html.escape(str(GTR))}…); "
        "measured-vs-model series are recomputed from the stored estimates and the run's data file.</p>"
        "</body></html>\n"
    )
