"""The labeling UI's parts without a browser: replay pacing, poses, the inset, the service link."""

from __future__ import annotations

import itertools
import json
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
import numpy as np
import pytest
from canned_http import answering

from collie.schemas import MAX_HOLD, MAX_TABS
from collie.tasks import BAD, NEUTRAL, get_task
from labeling_ui.claims import Claims
from labeling_ui.colours import PLAYED_RGB
from labeling_ui.guarded_tab import GuardedTab
from labeling_ui.inset import CLASS_RGB, END_RGB, NO_RULE_RGB, SIZE, inset_caption, render_inset, view_box
from labeling_ui.models import ModelError, Poser, replay_model, warm_models
from labeling_ui.playback import Player
from labeling_ui.regions import TINT_RGB, region_outline, tint_meshes
from labeling_ui.service import AuthRefused, ServiceDown, ServiceLink
from labeling_ui.tab import TabState

from .stack import Stack


def test_labeling_ui_imports_no_torch() -> None:
    code = "import sys, labeling_ui.cli, labeling_ui.app; assert 'torch' not in sys.modules, 'torch imported'"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_poser_interpolates_on_the_joint_manifold() -> None:
    model = replay_model("ant")
    rng = np.random.default_rng(0)
    qpos = np.tile(model.qpos0, (3, 1))
    qpos[:, :2] = [[0, 0], [1, 0], [2, 2]]
    for row in qpos:  # random unit torso quaternions
        q = rng.normal(size=4)
        row[3:7] = q / np.linalg.norm(q)
    poser = Poser(model, qpos)
    np.testing.assert_allclose(poser.configuration(1.0), qpos[1])
    half = poser.configuration(0.5)
    np.testing.assert_allclose(half[:2], [0.5, 0.0], atol=1e-9)
    assert abs(np.linalg.norm(half[3:7]) - 1) < 1e-9
    np.testing.assert_allclose(poser.configuration(99.0), qpos[2])  # clamped to the last frame
    assert poser.pose(0.0).xpos[1][0] == pytest.approx(0.0)


@pytest.mark.parametrize(
    ("env", "qpos", "message"),
    [("no_such_robot", np.zeros((2, 2)), "cannot build"), ("point", np.zeros((2, 5)), "nq=2")],
)
def test_unreplayable_segments_raise_model_error(env: str, qpos: np.ndarray, message: str) -> None:
    with pytest.raises(ModelError, match=message):
        Poser(replay_model(env), qpos)


class Recorder:
    def __init__(self) -> None:
        self.positions: list[float] = []
        self.frames: list[tuple[int, bool]] = []
        self.lock = threading.Lock()

    def render(self, position: float) -> None:
        with self.lock:
            self.positions.append(position)


def test_warm_models_compiles_ahead_and_names_what_fails() -> None:
    took = warm_models(("point", "no_such_robot"))
    assert np.isfinite(took["point"]) and np.isnan(took["no_such_robot"])
    stopped = threading.Event()
    stopped.set()
    assert warm_models(("humanoid",), stop=stopped) == {}  # a stopping UI compiles nothing more
    assert replay_model("point") is replay_model("point")  # compiled once, then shared


def test_player_paces_at_most_30_hz_and_loops() -> None:
    rec = Recorder()
    player = Player(rec.render, lambda f, p: rec.frames.append((f, p)), fps=20.0)
    player.load(20)
    assert rec.positions[:1] == [0.0]  # the first frame is drawn at once, by the caller (the thread may add more)

    def advanced_and_wrapped(positions: list[float]) -> bool:
        # it advanced; the rate itself is benchmarked (bench-labeling), not tested
        return len(positions) > 5 and any(b < a for a, b in itertools.pairwise(positions))

    deadline = time.monotonic() + 30  # 20 frames at 20 fps wrap after 1 s; a busy machine gets there later
    while True:
        with rec.lock:
            positions = list(rec.positions)
        if advanced_and_wrapped(positions) or time.monotonic() >= deadline:
            break
        time.sleep(0.05)
    player.close()
    assert advanced_and_wrapped(positions), positions
    assert max(positions) < 20  # within the segment
    assert rec.frames[0] == (0, True)


def test_player_step_seek_speed_and_stop_at_end() -> None:
    rec = Recorder()
    player = Player(rec.render, fps=20.0)
    player.load(10, play=False)
    player.step(3)
    assert player.position == 3.0 and not player.playing
    player.step(-10)
    assert player.position == 0.0
    player.seek(42)
    assert player.position == 9.0
    player.set_speed(100)
    assert player.speed == 4.0
    player.loop = False
    player.replay()
    deadline = time.monotonic() + 10  # 10 frames at 20 fps × 4 take 0.125 s
    while player.playing and time.monotonic() < deadline:
        time.sleep(0.02)
    assert not player.playing and player.position == 9.0
    player.autoplay = False  # a new segment then waits on its first frame
    player.load(10)
    assert not player.playing and player.position == 0.0 and rec.positions[-1] == 0.0
    player.close()


def test_inset_is_north_up_and_paints_the_task() -> None:
    task = get_task("north", "ant")
    image = render_inset(task, np.array([[0.0, 1.0], [0.0, 3.0]]), np.array([[0.0, 0.0], [0.0, 1.0]]))
    assert image.shape == (SIZE, SIZE, 3) and image.dtype == np.uint8
    top, bottom = image[5, SIZE // 2 + 20], image[-5, SIZE // 2 + 20]  # beside the drawn y axis
    assert tuple(top) == CLASS_RGB[NEUTRAL]  # north of the origin: the (neutral) wedge
    assert tuple(bottom) == CLASS_RGB[BAD]  # south: bad
    plain = render_inset(None, np.array([[0.0, 1.0], [0.0, 3.0]]), None)  # an instruction alone: no class shaded
    assert tuple(plain[5, SIZE // 2 + 20]) == tuple(plain[-5, SIZE // 2 + 20]) == NO_RULE_RGB
    assert NO_RULE_RGB not in CLASS_RGB.values()
    cx, cy, half = view_box(np.array([[10.0, 10.0]]))
    assert half >= 5 and 0 <= cx <= 10 and 0 <= cy <= 10  # holds the origin and the path
    # its end is a ring, not the 3D view's "played" pink (was a pink dot, read as where the robot is)
    colours = {tuple(p) for p in image.reshape(-1, 3)}
    assert PLAYED_RGB not in colours and END_RGB in colours


def test_the_inset_caption_gives_its_scale_and_where_the_segment_lies() -> None:
    """With only an instruction ("away from the east side") nothing is tinted, and the inset rescales
    per segment: the caption says how wide it is and where the segment runs, east and north."""
    caption = inset_caption(np.array([[3.0, -1.0], [4.5, -0.25]]), np.array([[0.0, 0.0], [3.0, -1.0]]))
    half = view_box(np.array([[3.0, -1.0], [4.5, -0.25]]), np.array([[0.0, 0.0], [3.0, -1.0]]))[2]
    assert caption.startswith(f"{2 * half:.3g} units across · the segment runs from (+3.00, -1.00) to (+4.50, -0.25)")
    assert "x east, y north of the origin (where the grey lines cross" in caption


def test_floor_map_and_region_outlines() -> None:
    task = get_task("north", "ant")
    ((rgb, vertices, faces),) = tint_meshes(task, 0.0, 0.0, 10.0, cells=20)  # bad only: north has no good
    assert rgb == TINT_RGB[0] and faces.max() < len(vertices)
    inside = vertices[faces].mean(axis=1)[:, :2]  # triangle centroids all lie in the bad area
    assert (task.classify(inside) == 0).all()
    assert tint_meshes(task, 0.0, 50.0, 1.0, cells=8) == []  # all inside the wedge
    # the tint's edge follows the region edge, not the grid's cells: the bad area outside range's
    # circle has its inner corners on the circle (to well within a cell's width)
    ring = get_task("range", "ant")
    (circle,) = [r for r in ring.to_dict()["regions"] if r["kind"] == "outside_disc"]
    (_, verts, _), *_ = tint_meshes(ring, *circle["centre"], 1.5 * circle["radius"], cells=40)
    radii = np.hypot(verts[:, 0] - circle["centre"][0], verts[:, 1] - circle["centre"][1])
    near = radii[radii < circle["radius"] + 1.0]
    assert len(near) > 20 and np.abs(near - circle["radius"]).max() < 0.05
    kinds = {r["kind"]: region_outline(r) for r in get_task("hole", "ant").to_dict()["regions"]}
    outline = kinds["disc"]
    assert outline is not None and outline.shape[1] == 3


def test_service_link_sorts_errors(stack: Stack) -> None:
    with pytest.raises(AuthRefused):
        ServiceLink(stack.api, "wrong").login()
    with pytest.raises(AuthRefused, match="trainer token"):
        ServiceLink(stack.api, "tr-token-0123456789").login()
    with pytest.raises(ServiceDown):
        ServiceLink("http://127.0.0.1:9", "x").login()
    link = ServiceLink(stack.api, stack.new_labeler("linked"))
    assert link.login().name == "linked"
    run = stack.post_run("point", 2)
    assert link.pick_run() is not None
    claim = link.claim(run.id)
    assert claim is not None
    link.submit(run.id, claim.query.query_id, 1, 1.5, "req-1")
    link.submit(run.id, claim.query.query_id, 1, 1.5, "req-1")  # a retry: no second event
    progress = link.progress(run.id, 0)
    assert (progress.session_done, progress.session_size, progress.total_done) == (1, 2, 1)
    assert len(stack.trainer.label_events(run.id)) == 1


def test_a_tab_too_many_keeps_the_services_reason(stack: Stack) -> None:
    token = stack.new_labeler("five-tabs")
    run = stack.post_run("point", MAX_HOLD * MAX_TABS + 2)
    for t in range(MAX_TABS):  # four tabs, each holding its segment and the next
        for hold in range(1, MAX_HOLD + 1):
            assert ServiceLink(stack.api, token, tab=f"tab-full-{t:04d}").claim(run.id, hold=hold) is not None
    claims = Claims(GuardedTab(TabState()), None, prefetch=True)  # type: ignore[arg-type]  # claim() needs no screen
    assert claims.claim(ServiceLink(stack.api, token, tab="tab-fifth-0000"), run) is None
    assert claims.refused is not None and f"your other tabs hold {MAX_HOLD * MAX_TABS} segments" in claims.refused


def test_cli_serves_reports_its_port_and_stops_on_sigterm(stack: Stack, tmp_path: Path) -> None:
    info = tmp_path / "new" / "ui.json"  # its folder is made, as `collie up` makes its --info-json's
    cmd = [sys.executable, "-m", "labeling_ui.cli"]
    args = ["--api", stack.api, "--port", "0", "--info-json", str(info), "--token", "tok&en"]
    proc = subprocess.Popen([*cmd, *args], stdout=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not info.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        served = json.loads(info.read_text())
        page = httpx.get(served["url"], timeout=10)
        assert page.status_code == 200 and "<html" in page.text.lower()  # viser's client
    finally:
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)  # it joins its warm-up compiles first
    assert proc.returncode == 0
    assert f"labeler URL: {served['url']}?token=tok%26en" in out
    assert [p.name for p in info.parent.iterdir()] == ["ui.json"]  # written whole: no partial file left


@pytest.mark.parametrize(
    ("flags", "said"),
    [
        (["--fps", "0"], "argument --fps: 0 must be > 0 and ≤ 1000"),
        (["--fps", "-3"], "argument --fps: -3 must be > 0"),
        (["--lease-s", "-1"], "argument --lease-s: -1 must be > 0 and ≤ 3600"),  # the service's bounds
        (["--run", "0"], "argument --run: 0 is not an id"),
        (["--host", "999.9.9.9"], "argument --host: '999.9.9.9' is not an IPv4 address"),
        (["--host", "192.0.2.1"], "--host 192.0.2.1 is not an address of this machine ("),  # TEST-NET-1: no one's
        (["--info-json", "{tmp}"], "--info-json {tmp} is a folder; give a file path"),
        (["--warm", "point,moon"], "--warm: unknown env 'moon'; valid: point, ant,"),
        (["--info-json", "{tmp}/file/ui.json"], "cannot create the folder of --info-json {tmp}/file: "),
    ],
)
def test_what_the_ui_cannot_serve_with_is_refused_in_one_line_before_it_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flags: list[str], said: str
) -> None:
    from collie.cli import main

    (tmp_path / "file").write_text("")
    flags = [f.format(tmp=tmp_path) for f in flags]
    ended: list[BaseException] = []

    def command() -> None:  # in a thread: a UI that starts after all (or hangs binding) fails the test, not hangs it
        try:
            main(["label-ui", "--api", "http://127.0.0.1:9", "--port", "0", "--warm", "point", *flags])
        except BaseException as exc:  # argparse's exit, or the command's own line
            ended.append(exc)

    thread = threading.Thread(target=command, daemon=True)
    thread.start()
    thread.join(30)
    assert ended and isinstance(ended[0], SystemExit), ended or "not refused: still running after 30 s"
    code = ended[0].code
    assert code == 2 and said.format(tmp=tmp_path) in capsys.readouterr().err  # a usage error, as argparse's
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]  # nothing written


def test_a_port_in_use_is_said_with_the_port_served_instead(stack: Stack, tmp_path: Path) -> None:
    info = tmp_path / "ui.json"
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        taken = busy.getsockname()[1]
        cmd = [sys.executable, "-m", "labeling_ui.cli", "--api", stack.api, "--port", str(taken)]
        proc = subprocess.Popen([*cmd, "--info-json", str(info)], stdout=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + 30
            while not info.exists() and time.monotonic() < deadline:
                time.sleep(0.1)
            served = json.loads(info.read_text())["port"]
        finally:
            proc.send_signal(signal.SIGTERM)
            out, _ = proc.communicate(timeout=60)  # it joins its warm-up compiles first
    assert served != taken
    assert f"port {taken} is in use; serving on port {served} instead" in out


def ui_start_warnings(api: str, *flags: str) -> list[str]:
    """The warnings a real `collie label-ui` says as it starts (it starts all the same)."""
    cmd = [sys.executable, "-m", "collie.cli", "label-ui", "--api", api, "--port", "0", "--warm", "", *flags]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for line in proc.stdout:  # type: ignore[union-attr]  # viser's box, then ours
            if line.startswith("collie labeling UI: http://"):
                break
        else:
            pytest.fail("collie label-ui ended before it served")
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)  # 20 s ran out once under a loaded machine
    assert "Traceback" not in err, err  # stopped by SIGTERM, perhaps before its handler is in place
    return [line for line in err.splitlines() if line.startswith("collie label-ui: warning: ")]


def test_the_ui_warns_at_start_of_a_service_it_cannot_use(stack: Stack) -> None:
    """Was: the UI started and printed its URL without a word for any of these."""
    with socket.socket() as gone:
        gone.bind(("127.0.0.1", 0))
        nobody = f"http://127.0.0.1:{gone.getsockname()[1]}"  # bound, never listening: refused
        said = ui_start_warnings(nobody)
    assert said == [
        f"collie label-ui: warning: the labeling service at {nobody} does not answer (connection refused); "
        "the UI starts, and labels once it does"
    ]
    where = f"collie label-ui: warning: the labeling service at {stack.api}"
    assert ui_start_warnings(stack.api, "--token", "wrong-token-0123456789") == [
        f"{where} refused --token (401: unknown or revoked token): the labeler URL will not sign in"
    ]
    assert ui_start_warnings(stack.api, "--token", stack.new_labeler("probe"), "--run", "77") == [
        f"{where} has no run 77"
    ]
    assert ui_start_warnings(f"{stack.api}/zzz") == [
        f"collie label-ui: warning: {stack.api}/zzz is not a collie service (404 on /zzz/api/health); check --api"
    ]


def test_an_answer_damaged_on_the_way_is_a_warning_and_the_ui_starts() -> None:
    """A proxy in front of the service sends a body that is not what its header says (httpx's
    DecodingError, a GarbledAnswer of the client): one warning naming the service and what was wrong.
    Was: the check's thread died with a traceback on stderr; then "could not check" and httpx's repr."""
    with answering(200, b"not gzip at all", {"Content-Encoding": "gzip"}) as api:
        said = ui_start_warnings(api)
    assert len(said) == 1, said
    where = f"collie label-ui: warning: the labeling service at {api} sent an answer damaged on the way"
    assert said[0].startswith(f"{where}, a proxy between? (GET {api}/api/health: the body is not in its declared ")
    assert said[0].endswith("; the UI starts, and labels once it does")


def test_a_page_that_is_not_the_services_is_a_warning_naming_it() -> None:
    page = b"<html><head><title>Welcome to nginx!</title></head></html>"
    with answering(200, page, {"Content-Type": "text/html"}) as api:
        said = ui_start_warnings(api)
    assert said == [
        f"collie label-ui: warning: {api} is not a collie service (GET {api}/api/health answered 200 with an HTML "
        "page (Welcome to nginx!), not JSON); check --api"
    ]


def test_fits_the_collie_command(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    from collie import cli

    monkeypatch.setitem(cli.SUBCOMMANDS, "label-ui", ("labeling_ui.cli", "serve the labeling UI"))
    with pytest.raises(SystemExit) as exit_:
        cli.main(["label-ui", "--help"])
    assert exit_.value.code == 0 and "--api" in capsys.readouterr().out
