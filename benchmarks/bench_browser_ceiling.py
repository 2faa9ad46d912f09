"""What limits the labeling page's frame rate in this machine's browser (issue 15's "≥ 25 fps, or
the measured limit with its reason"): viser pages with nothing of ours in them, in the same
headless Chromium (software WebGL) and viewport as `bench_labeling.py`.

For each case, frames the page draws per second (requestAnimationFrame) while the server either
sends nothing or moves nodes at `--hz` (one atomic batch per tick, as a replay tick is):
  - an empty scene, still and with one box moved;
  - `--static` boxes that never move beside one moved box (the labeling page's ant scene has
    about 30 nodes: 14 frames, 9 mesh batches, 6 line sets, the grid, a label, the floor);
  - the same with `--moved` boxes moved per tick (an ant tick updates about 20 properties: 9 mesh
    batches' positions and orientations, the trail, the followed frame).
viser draws on demand (react-three-fiber's frameloop="demand"): a page with nothing changing
draws nothing, so a still page's rate is requestAnimationFrame's, not a drawing rate. Every
update makes the page draw the whole scene once.

Then the labeling page itself (a real service and labeling UI, an ant segment at 1×), with its
parts taken away one after another while it plays: as labelers see it; without the floor grid;
and without the paths and the region tint; and without the robot (the followed world frame still
moves every tick, so the page still draws every tick). Last, the page as labelers see it at half
the pixels per side (viser's `?fixedDpr=0.5`). What each removal gains is what that part costs
a frame.

    python benchmarks/bench_browser_ceiling.py          # make bench-browser-ceiling
Writes runs/bench/browser_ceiling.json: `<case>_fps` for each case above — `empty_still_fps`,
`empty_one_moved_fps`, `static<S>_still_fps`, `static<S>_one_moved_fps`, `static<S>_<M>_moved_fps`
(S = --static, M = --moved; static30_20_moved_fps by default) — and `ant_as_seen_fps`,
`ant_no_grid_fps`, `ant_no_grid_paths_fps`, `ant_no_robot_fps`, `ant_half_resolution_fps`.
Settings: hz, static, moved, seconds, viewport, and the Chromium version.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

import viser

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
import ui.page
from chromium import chromium
from record import record
from ui.page import open_labeler, wait_segment
from ui.stack import real_stack

FPS_JS = """(ms) => new Promise((done) => {
  let n = 0; const t0 = performance.now();
  const tick = (t) => { n += 1; if (t - t0 < ms) requestAnimationFrame(tick); else done(n / ((t - t0) / 1000)); };
  requestAnimationFrame(tick);
})"""  # frames the page draws per second over `ms`


def page_fps(browser: object, n_static: int, n_moved: int, hz: float, seconds: float, viewport: dict) -> float:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    server.scene.configure_environment_map(hdri=None)  # as the labeling UI does
    server.scene.configure_default_lights(cast_shadow=False)
    for i in range(n_static):
        server.scene.add_box(
            f"/still/b{i}",
            dimensions=(0.1,) * 3,
            position=(0.15 * i, 0.5, 0.0),
            cast_shadow=False,
            receive_shadow=False,
        )
    movers = [
        server.scene.add_box(f"/mover{i}", dimensions=(0.1,) * 3, position=(0.15 * i, 0.0, 0.0), cast_shadow=False)
        for i in range(n_moved)
    ]
    stop = threading.Event()

    def move() -> None:
        tick = 0
        while n_moved and not stop.wait(1.0 / hz):
            tick += 1
            with server.atomic():  # one batch per tick, as a replay tick is
                for i, mover in enumerate(movers):
                    mover.position = (0.15 * i, 0.0, 0.01 * (tick % 100))

    thread = threading.Thread(target=move, daemon=True)
    thread.start()
    try:
        page = browser.new_page(viewport=viewport)  # type: ignore[attr-defined]
        page.goto(f"http://127.0.0.1:{server.get_port()}/")
        page.wait_for_selector("canvas", timeout=60_000)
        page.wait_for_timeout(1500)  # past the first frames' shader compiles
        fps = float(page.evaluate(FPS_JS, seconds * 1000))
        page.context.close()
        return fps
    finally:
        stop.set()
        thread.join(2.0)
        server.stop()


def ant_parts(browser: object, seconds: float) -> dict[str, float]:
    """Frames the labeling page draws for an ant segment at 1×, its parts taken away one by one
    (through the tab's ReplayScene and mjviser's handles), then at half resolution."""
    rates: dict[str, float] = {}
    with tempfile.TemporaryDirectory() as tmp, real_stack(Path(tmp) / "bench.db") as stack:
        run = stack.post_run("ant", 1, seed=12)
        app = stack.ui(run.id)
        url = app.labeler_url(stack.new_labeler("ceiling"))
        page = open_labeler(browser, url)
        wait_segment(page, timeout_s=90)
        rates["as_seen"] = _fps_after(page, seconds)
        scene = app.sessions[max(app.sessions)].scene  # this page's
        # the grid is mjviser's floor plane; a node added under its name replaces it
        scene.client.scene.add_grid("/fixed_bodies/world/floor", visible=False)
        rates["no_grid"] = _fps_after(page, seconds)
        for handle in scene._overlays + scene._floor:
            handle.visible = False
        rates["no_grid_paths"] = _fps_after(page, seconds)
        for group in scene._mj._mesh_groups:
            group.handle.visible = False
        rates["no_robot"] = _fps_after(page, seconds)
        page.context.close()
        page = open_labeler(browser, url + "&fixedDpr=0.5")  # viser's fixed device-pixel ratio
        wait_segment(page, timeout_s=90)
        rates["half_resolution"] = _fps_after(page, seconds)
        page.context.close()
    return rates


def _fps_after(page: object, seconds: float) -> float:
    page.wait_for_timeout(1500)  # type: ignore[attr-defined]  # the change has reached the page
    return float(page.evaluate(FPS_JS, seconds * 1000))  # type: ignore[attr-defined]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--static", type=int, default=30, help="nodes that never move, beside the moved one")
    parser.add_argument("--moved", type=int, default=20, help="nodes moved per tick in the last case (ant: ≈ 20)")
    parser.add_argument("--hz", type=float, default=30.0, help="updates per second of the moved node (a 1x replay)")
    parser.add_argument("--seconds", type=float, default=3.0, help="seconds to count frames, per case")
    parser.add_argument("--viewport", default="1280x800")
    args = parser.parse_args()
    width, height = (int(v) for v in args.viewport.split("x"))
    viewport = {"width": width, "height": height}
    n = args.static
    cases = {
        "empty_still": (0, 0),
        "empty_one_moved": (0, 1),
        f"static{n}_still": (n, 0),
        f"static{n}_one_moved": (n, 1),
        f"static{n}_{args.moved}_moved": (n, args.moved),
    }
    figures: dict[str, float] = {}
    settings = {"hz": args.hz, "static": args.static, "moved": args.moved, "seconds": args.seconds}
    with chromium() as browser:
        settings |= {"viewport": args.viewport, "chromium": browser.version}
        print(f"bench-browser-ceiling · chromium {browser.version} · viewport {args.viewport} · {args.hz:g} Hz")
        for name, (n_static, n_moved) in cases.items():
            start = time.perf_counter()
            fps = page_fps(browser, n_static, n_moved, args.hz, args.seconds, viewport)
            figures[f"{name}_fps"] = fps
            print(f"  {name:<24} {fps:6.1f} frames/s   ({time.perf_counter() - start:.0f} s)", flush=True)
        ui.page.VIEWPORT = viewport
        print("the labeling page, an ant segment playing at 1x (parts taken away one after another):")
        for name, fps in ant_parts(browser, args.seconds).items():
            figures[f"ant_{name}_fps"] = fps
            print(f"  ant {name:<20} {fps:6.1f} frames/s", flush=True)
    record("browser_ceiling", figures, settings)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
