"""Interactive pieces of the single-file report: plotly figures embedded as JSON, plotly.js embedded once, and a
small script that draws the figures and makes the tables sortable and filterable.

Everything works offline: plotly.js comes from the `plotly` package (`plotly.offline.get_plotlyjs()`), inlined in
one `<script>` element; each figure is a `<script type="application/json">` element beside its `<div>`. Texts in the
JSON are escaped so that no `</script>` (or `<!--`) written by a suite can end the element early
(`script_json`); texts shown by plotly (trace names, hover texts, titles) are HTML-escaped by the figure builders,
since plotly renders a subset of HTML in them.
"""

from __future__ import annotations

import base64
import functools
import html
import json
import math
from collections.abc import Mapping

import numpy as np

#: Characters replaced by JSON escapes inside a script element: `<` `>` `&` (no `</script>`, `<!--`, `]]>`) and the
#: line separators JavaScript parsers once rejected in strings.
_SCRIPT_ESCAPES = {"<": "\\u003c", ">": "\\u003e", "&": "\\u0026", "\u2028": "\\u2028", "\u2029": "\\u2029"}

#: plotly's options for every figure: no link to plotly's site, no logo; the mode bar only on hover.
PLOT_CONFIG = {"displaylogo": False, "responsive": True, "showLink": False, "showSendToCloud": False}

#: Draws every figure (div.plot with its JSON beside it) and makes each table.sortable sortable (click a
#: heading) and, above 8 rows, filterable (a text box: rows containing every word typed are kept).
BOOT_JS = """
(function () {
  "use strict";
  function draw(div) {
    var fig = JSON.parse(document.getElementById(div.dataset.figure).textContent);
    return Plotly.newPlot(div, fig.data, fig.layout, fig.config).then(function (gd) {
      return fig.frames ? Plotly.addFrames(gd, fig.frames) : gd;
    });
  }
  function sortable(table) {
    var body = table.tBodies[0];
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, col) {
      th.title = "click to sort";
      th.addEventListener("click", function () {
        var up = th.dataset.sort !== "up";
        Array.prototype.forEach.call(table.tHead.rows[0].cells, function (c) { delete c.dataset.sort; });
        th.dataset.sort = up ? "up" : "down";
        var rows = Array.prototype.slice.call(body.rows);
        var key = function (r) {
          var s = r.cells[col] ? r.cells[col].textContent.trim() : "";
          var v = Number(s.replace(/^<=\\s*/, ""));  // an upper bound `<= x` sorts as x
          return s === "" || s === "\\u2013" ? [2, 0] : isNaN(v) ? [1, s] : [0, v];
        };
        rows.sort(function (a, b) {
          var ka = key(a), kb = key(b);
          if (ka[0] !== kb[0]) { return ka[0] - kb[0]; }
          var c = ka[0] === 1 ? String(ka[1]).localeCompare(String(kb[1])) : ka[1] - kb[1];
          return up ? c : -c;
        });
        rows.forEach(function (r) { body.appendChild(r); });
      });
    });
    if (body.rows.length > 8) {
      var box = document.createElement("input");
      box.type = "search";
      box.className = "filter";
      box.placeholder = "filter rows (" + body.rows.length + ")";
      box.addEventListener("input", function () {
        var words = box.value.toLowerCase().split(/\\s+/).filter(Boolean);
        Array.prototype.forEach.call(body.rows, function (r) {
          var text = r.textContent.toLowerCase();
          r.hidden = !words.every(function (w) { return text.indexOf(w) >= 0; });
        });
      });
      table.parentNode.insertBefore(box, table);
    }
  }
  // plotly.js rejects the promise of an animation that another one interrupts (Pause, or a slider step during
  // Play) with no reason at all; that is how its buttons work, not an error.
  window.addEventListener("unhandledrejection", function (e) {
    if (e.reason === undefined) { e.preventDefault(); }
  });
  document.querySelectorAll("table.sortable").forEach(sortable);
  var pending = Array.prototype.map.call(document.querySelectorAll("div.plot"), draw);
  Promise.all(pending).then(function () { document.body.dataset.plotsReady = "yes"; });
})();
"""


@functools.cache
def plotly_js() -> str:
    """plotly.js (minified) as bundled with the `plotly` package, to inline once per page."""
    from plotly.offline import get_plotlyjs

    return get_plotlyjs()


def plotly_version() -> str:
    """The `plotly` package's version (the plotly.js it bundles is in the page)."""
    import plotly

    return str(plotly.__version__)


def _plain(value: object) -> object:
    """value with numpy scalars as Python ones and non-finite floats as None (JSON has no NaN)."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_plain(v) for v in value.tolist()]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    return value


def script_json(value: object) -> str:
    """JSON text of value safe inside an HTML `<script>` element: `<`, `>`, `&`, U+2028 and U+2029 as escapes."""
    text = json.dumps(_plain(value), ensure_ascii=False, allow_nan=False, separators=(",", ":"))
    return "".join(_SCRIPT_ESCAPES.get(ch, ch) for ch in text)


def typed_array(values: np.ndarray, dtype: str = "f4") -> dict[str, str]:
    """A plotly typed array (`{"dtype", "bdata"}`: little-endian values, base64) of values; dtype `f4`, `f8`,
    `i4` or `u4`. About 5.3 bytes per f4 value in the page against 7 to 10 for decimal text."""
    kinds = {"f4": "<f4", "f8": "<f8", "i4": "<i4", "u4": "<u4"}
    if dtype not in kinds:
        raise ValueError(f"typed array dtype {dtype!r}: expected one of {sorted(kinds)}")
    data = np.ascontiguousarray(np.asarray(values).ravel(), dtype=kinds[dtype])
    return {"dtype": dtype, "bdata": base64.b64encode(data.tobytes()).decode("ascii")}


def text(value: object) -> str:
    """A suite-provided text for plotly (names, hover text, titles): HTML-escaped, as plotly renders some tags."""
    return html.escape(str(value))


def plot_div(figure: Mapping[str, object], div_id: str, height_px: int = 420) -> str:
    """The `<div>` plotly draws `figure` (data, layout, optional frames) into, and the figure as JSON beside it.

    div_id must be a page-unique id made of letters, digits and `-` (not suite-provided text).
    """
    if not div_id.replace("-", "").isalnum():
        raise ValueError(f"plot id {div_id!r}: expected letters, digits and '-'")
    fig = {"data": figure.get("data", []), "layout": figure.get("layout", {}), "config": PLOT_CONFIG}
    if figure.get("frames"):
        fig["frames"] = figure["frames"]
    return (f'<div class="plot" id="{div_id}" data-figure="{div_id}-json" style="height:{height_px}px"></div>\n'
            f'<script type="application/json" id="{div_id}-json">{script_json(fig)}</script>')


def page_scripts() -> str:
    """The scripts every page ends with: plotly.js, then the boot script (`BOOT_JS`)."""
    return f"<script>{plotly_js()}</script>\n<script>{BOOT_JS}</script>"
