"""A class has one colour on every screen: the dashboard's, the plots' and the labeling UI's."""

from __future__ import annotations

import json
import re
from pathlib import Path

from collie.class_colours import PALE, STRONG, to_rgb
from labeling_ui import inset, regions
from trainer import plots

REGIONS_JS = Path(__file__).resolve().parents[2] / "web" / "js" / "regions.js"


def js_array(name: str) -> list[str]:
    found = re.search(rf"export const {name} = (\[[^\]]*\]);", REGIONS_JS.read_text())
    assert found, f"{name} not found in {REGIONS_JS}"
    return json.loads(found.group(1))


def test_dashboard_plots_and_labeling_ui_share_the_class_colours() -> None:
    assert js_array("CLASS_COLOURS") == [STRONG[c] for c in range(3)]
    assert js_array("FILL") == [PALE[c] for c in range(3)]
    assert plots.CLASS_COLOURS == STRONG
    assert {c: to_rgb(PALE[c]) for c in range(3)} == inset.CLASS_RGB
    assert {c: to_rgb(STRONG[c]) for c in range(3)} == regions.EDGE_RGB
    assert {0: to_rgb(PALE[0]), 2: to_rgb(PALE[2])} == regions.TINT_RGB
    assert to_rgb("#e6b800") == (230, 184, 0)
