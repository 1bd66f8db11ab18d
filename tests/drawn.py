"""What a served Bokeh figure really drew: its plot frame's pixels, read from a browser screenshot.

A table or a data source can be right while the canvas stays blank (a WebGL glyph without a GPU draws
nothing). :func:`missing_colours` screenshots the frame of the figure whose title starts with a given text,
paints its legends white (a legend's swatches are drawn even when the glyphs are not), and counts the
pixels of each colour the legend promises. Used by the browser tests and by
``benchmarks/teacher_screenshots.py``, with the glyphs each tab's figures promise (the constants below:
legend label -> (colour, alpha), read from the views' own colours).
"""

from __future__ import annotations

import io
import time
from collections.abc import Mapping

import numpy as np

from uam_studio.app.battery_lab.nasa import NASA_COLORS
from uam_studio.app.battery_lab.view import EOD_COLOR, FAMILY_COLORS
from uam_studio.app.fleet.view import COLORS
from uam_studio.app.fly.many import BLIND_COLOR, DIAGONAL_COLOR, OPERATOR_COLOR, RATE_COLOR
from uam_studio.app.fly.view import EVENT_COLOR
from uam_studio.app.planner.map_geometry import FAILED_COLOR
from uam_studio.app.style import MEASURED_COLOR, PHYSICS_COLOR, PREDICTED_COLOR

BLACK = ("#000000", 1.0)
# The Planner's voltage figure ("Voltage: physics ...").
PLANNER_VOLTAGE = {"physics": (PHYSICS_COLOR, 1.0), "Dynaformer": (PREDICTED_COLOR, 1.0), "EOD": (FAILED_COLOR, 1.0)}


def lab_voltage(labels: list[str]) -> dict[str, tuple[str, float]]:
    """The Battery lab's voltage figure: its family's curves in legend order (``None``: a curve not asked
    for, e.g. one that ends under the others' first sample), the black "this setting" curve and the EOD line."""
    return {label: (FAMILY_COLORS[k], 0.8) for k, label in enumerate(labels) if label is not None} | {
        "this setting": BLACK, "EOD": (EOD_COLOR, 1.0)}


# Varying R0: its 0.45 ohm curve ends after 0.2 min, under the others' first sample, and is not asked for;
# R0 does not change the current, which shows as the black curve alone.
LAB_R0_VOLTAGE = lab_voltage(["R0 0.017 ohm", "R0 0.1 ohm", "R0 0.2 ohm", "R0 0.3 ohm"])
LAB_CURRENT = {"this setting": BLACK}
# The Fly tab's voltage figure after a flight with an injected wind change.
FLY_VOLTAGE = {"predicted (operator)": (PREDICTED_COLOR, 1.0), "true (hidden)": (PHYSICS_COLOR, 1.0),
               "measured": (MEASURED_COLOR, 0.8), "EOD cut-off": (FAILED_COLOR, 1.0),
               "wind change": (EVENT_COLOR, 1.0)}
# The Fly tab's many flights: the breach rate against the declared risk, and the priority served.
MANY_RATES = {"rate = risk": (DIAGONAL_COLOR, 1.0), "flown (95% interval)": (RATE_COLOR, 1.0)}
MANY_SERVED = {"operator": (OPERATOR_COLOR, 1.0), "pre-flight plan, blind": (BLIND_COLOR, 1.0)}
# Retrain's dashed reference line, on each learning-curve figure.
RETRAIN_ORACLE = {"exact oracle (this map)": ("#333333", 1.0)}
# The Fleet's per-day chart and its packs' belief against truth.
FLEET_DAYS = {"health-aware": (COLORS["aware"], 1.0), "health-blind": (COLORS["blind"], 1.0),
              "hindsight": (COLORS["hindsight"], 1.0), "upper bound": BLACK}
FLEET_PACKS = {"belief": (COLORS["aware"], 1.0), "truth (hidden)": BLACK}
# The Battery lab's real NASA discharge (a mid-life one: persistence drawn too).
NASA_LAB = {label: (NASA_COLORS[key], 1.0) for label, key in (
    ("measured", "measured"), ("predicted", "predicted"), ("bound, 5% risk", "bound"),
    ("persistence", "persistence"), ("progpy default", "progpy"), ("EOD", "EOD"))}

# The plot frame (page pixels) of the first figure whose title starts with the argument, and the boxes
# (the same coordinates) of its legends; null if there is no such figure or it is not laid out.
JS_FRAME_AND_LEGENDS = """(title) => {
  for (const v of window.Bokeh.index.all_views()) {
    const m = v.model;
    if (!((m.type === 'Figure' || m.type === 'Plot') && m.title && m.title.text && m.title.text.startsWith(title)))
      continue;
    const r = v.el.getBoundingClientRect(), f = v.frame.bbox;
    if (!r.width || !f.width) return null;
    const legends = [];
    for (const rv of v.renderer_views.values())
      if (rv.model.type === 'Legend' && rv.bbox)
        legends.push({left: r.left + rv.bbox.left, top: r.top + rv.bbox.top,
                      width: rv.bbox.width, height: rv.bbox.height});
    return {left: r.left + f.left, top: r.top + f.top, width: f.width, height: f.height, legends,
            webgl: m.output_backend === 'webgl'};
  }
  return null;
}"""


def rgb(colour: str, alpha: float = 1.0) -> np.ndarray:
    """``#rrggbb`` drawn at ``alpha`` over a white background, as an RGB triple (0-255)."""
    c = np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)], dtype=float)
    return alpha * c + (1.0 - alpha) * 255.0


def frame_pixels(page, title: str) -> np.ndarray:
    """The plot frame of the figure titled ``title...`` as an (height, width, 3) uint8 array, legends
    painted white. Scrolls the figure into view first."""
    from PIL import Image

    page.wait_for_function(f"() => ({JS_FRAME_AND_LEGENDS})({title!r}) !== null")
    page.evaluate("""(title) => { for (const v of window.Bokeh.index.all_views())
        if (v.model.title && v.model.title.text && v.model.title.text.startsWith(title)) {
          v.el.scrollIntoView({block: 'center'}); return; } }""", title)
    page.wait_for_timeout(300)  # a repaint after the scroll
    box = page.evaluate(JS_FRAME_AND_LEGENDS, title)
    clip = {k: box[k] for k in ("left", "top", "width", "height")}
    png = page.screenshot(clip={"x": clip["left"], "y": clip["top"], "width": clip["width"],
                                "height": clip["height"]})
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).copy()
    for lg in box["legends"]:
        x0, y0 = int(lg["left"] - clip["left"]), int(lg["top"] - clip["top"])
        img[max(0, y0):max(0, y0 + int(lg["height"]) + 2), max(0, x0):max(0, x0 + int(lg["width"]) + 2)] = 255
    return img


def colour_count(img: np.ndarray, colour: str, alpha: float = 1.0, tol: float = 60.0) -> int:
    """Pixels of ``img`` within ``tol`` (largest channel difference, 0-255) of ``colour`` at ``alpha``: a
    thin or dotted line's antialiased pixels sit 40-60 away from its colour."""
    return int((np.abs(img.astype(float) - rgb(colour, alpha)).max(axis=2) <= tol).sum())


def missing_colours(page, title: str, colours: Mapping[str, tuple[str, float]], min_px: int = 12) -> dict[str, int]:
    """The entries of ``colours`` (label -> (``#rrggbb``, alpha)) with fewer than ``min_px`` pixels of
    their colour inside the frame of the figure titled ``title...``: label -> pixels found. Empty when
    every promised glyph is drawn."""
    img = frame_pixels(page, title)
    counts = {label: colour_count(img, c, a) for label, (c, a) in colours.items()}
    return {label: n for label, n in counts.items() if n < min_px}


def assert_drawn(page, title: str, colours: Mapping[str, tuple[str, float]], min_px: int = 12,
                 timeout_s: float = 20.0) -> None:
    """Fail, naming the figure and each missing glyph, unless every entry of ``colours`` is drawn within
    ``timeout_s`` (a figure's data may arrive in a later document patch)."""
    deadline = time.monotonic() + timeout_s
    while True:
        missing = missing_colours(page, title, colours, min_px)
        if not missing or time.monotonic() > deadline:
            break
        page.wait_for_timeout(500)
    assert not missing, f"figure {title!r}: not drawn (pixels of its colour in the plot frame): {missing}"
