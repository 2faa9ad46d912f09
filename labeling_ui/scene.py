"""One browser's 3D replay: the robot (built by mjviser), the trail, the earlier path and the task's
regions on the floor.

Every node is client-scoped (added through the ClientHandle), so each labeler sees their own
segment. mjviser keeps the tracked body at the origin by moving the world under it, which makes
the camera follow the robot; our overlays hang under its world frame (/fixed_bodies) so they move
with the floor.
"""

from __future__ import annotations

import copy
import threading
import time
from collections.abc import Hashable
from typing import Any, cast

import mujoco
import numpy as np
import viser
from mjviser import ViserMujocoScene
from mjviser.conversions import is_fixed_body

from labeling_ui.colours import EARLIER_RGB, NORTH_RGB, PLAYED_RGB, TO_COME_RGB
from labeling_ui.models import Poser, replay_model, robot_size
from labeling_ui.regions import FLOOR_Z, edge_rgb, on_floor, region_outline

OVERLAY = "/fixed_bodies/collie"
COMPASS = "/collie_north"  # outside the world frame: it stays with the followed robot
SEGMENT_RGB, TRAIL_RGB = TO_COME_RGB, PLAYED_RGB
GRID_RGB = (120, 95, 95)
Tint = list[tuple[tuple[int, int, int], np.ndarray, np.ndarray]]


def polyline(points: np.ndarray) -> np.ndarray:
    """(N, 3) points → (N-1, 2, 3) line segments joining them in order."""
    return np.stack([points[:-1], points[1:]], axis=1)


def south_view(size: float = 0.0) -> tuple[float, float, float]:
    """The camera's place for a robot of `size`: due south of it and above, far enough to frame it
    (north up the screen, as in the inset); the server's first view is the smallest one."""
    distance = max(5.0, 5.0 * size)
    return (0.0, -distance, 0.6 * distance)


class ReplayScene:
    """The 3D view of one client. `load(env)` builds the robot once per env (reused across that
    env's segments); `set_segment` draws a segment's paths; `show(position)` poses the robot."""

    def __init__(self, client: viser.ClientHandle) -> None:
        self.client = client
        self.env: str | None = None
        self.build_s = 0.0
        self._mj: ViserMujocoScene | None = None
        self._poser: Poser | None = None
        self._tracked = 1
        self._size = 1.0
        self._trail_xyz = np.zeros((0, 3))
        self._trail: viser.LineSegmentsHandle | None = None
        self._overlays: list[viser.SceneNodeHandle] = []  # this segment's paths
        self._floor: list[viser.SceneNodeHandle] = []  # the task's regions around it
        self._floor_key: Hashable = None
        self._lock = threading.RLock()
        self.shadows = False  # shadow maps halve the frame rate of software-WebGL browsers

    def load(self, env: str) -> mujoco.MjModel:
        """The env's model, its robot in the scene (rebuilt only when the env changes)."""
        model = replay_model(env)
        with self._lock:
            if env == self.env and self._mj is not None:
                return model
            start = time.perf_counter()
            self.client.scene.reset()
            self._overlays, self._floor, self._floor_key, self._trail = [], [], None, None
            # mjviser's scene takes a server; a ClientHandle offers the same scene/atomic/flush
            # surface, which keeps every node local to this browser. It gets its own copy of the
            # model because it rescales the model's visual options in place.
            self._mj = ViserMujocoScene(cast(viser.ViserServer, self.client), copy.copy(model), num_envs=1)
            # mjviser lights with an HDR environment map, whose prefiltering stalls software-WebGL
            # browsers for seconds; viser's default lights are enough for a replay
            self.client.scene.configure_environment_map(hdri=None)
            self.set_shadows(self.shadows)
            self._tracked = next((b for b in range(model.nbody) if not is_fixed_body(model, b)), 0)
            self._size = robot_size(model)
            self._add_compass()
            self.aim_camera()
            self.env = env
            self.build_s = time.perf_counter() - start
            return model

    @property
    def floor_key(self) -> Hashable:
        return self._floor_key

    def set_shadows(self, on: bool) -> None:
        self.shadows = on
        self.client.scene.configure_default_lights(cast_shadow=on)

    def aim_camera(self) -> None:
        """Frame the robot (it sits at the origin) from due south, so north (+y) points up the
        screen as it does in the inset; the robot is followed by moving the world, so north stays
        up unless the labeler turns the view (the reset-view button turns it back). viser's
        per-client camera can only be moved once the browser has reported its camera; before that
        the server's initial camera (app.py, the same view) applies."""
        camera = self.client.camera
        if camera.update_timestamp == 0.0:
            return
        # position first: setting it shifts look_at along, so look_at is set after it
        camera.up_direction = (0.0, 0.0, 1.0)
        camera.position = south_view(self._size)
        camera.look_at = (0.0, 0.0, 0.0)

    def _add_compass(self) -> None:
        """A north arrow on the floor beside the robot, with an N at its tip."""
        r = max(1.0, 1.5 * self._size)
        head = 0.25 * r
        tip = (0.0, 2.0 * r, FLOOR_Z)
        lines = np.array(
            [[(0.0, r, FLOOR_Z), tip], [(-head, 2.0 * r - head, FLOOR_Z), tip], [(head, 2.0 * r - head, FLOOR_Z), tip]],
            np.float32,
        )
        self.client.scene.add_line_segments(
            f"{COMPASS}/arrow", lines, NORTH_RGB, thickness=4.0, thickness_units="screen"
        )
        self.client.scene.add_label(f"{COMPASS}/N", "N", position=(0.0, 2.0 * r + 0.3 * r, FLOOR_Z))

    def set_segment(self, poser: Poser, earlier_xy: np.ndarray | None) -> None:
        """Draw a segment: its whole path and the trajectory's earlier path."""
        with self._lock, self.client.atomic():
            self._poser = poser
            root = np.array([poser.pose(i).xpos[self._tracked].copy() for i in range(poser.n_frames)])
            self._trail_xyz = on_floor(root[:, :2])
            for handle in self._overlays:
                handle.remove()
            self._overlays = [self._lines("segment", self._trail_xyz, SEGMENT_RGB, 2.0)]
            if earlier_xy is not None and len(earlier_xy) > 1:
                self._overlays.append(self._lines("earlier", on_floor(earlier_xy), EARLIER_RGB, 2.0))
            self._trail = None
            self.client.scene.set_global_visibility(True)

    def set_floor(self, key: Hashable, task: dict[str, Any] | None, tint: Tint, grid: np.ndarray | None) -> None:
        """The task's region edges (Task.to_dict()), `tint`: flat meshes (colour, vertices, faces)
        on the floor, and `grid`: (N, 2, 3) grid lines over the tint. Sent only when `key` (what
        they were computed from) changes, so consecutive segments in one area cost nothing here."""
        with self._lock:
            if key == self._floor_key:
                return
            with self.client.atomic():
                for handle in self._floor:
                    handle.remove()
                self._floor = []
                for i, region in enumerate(task["regions"] if task else []):
                    outline = region_outline(region)
                    if outline is not None:
                        self._floor.append(self._lines(f"region{i}", outline, edge_rgb(region, task), 3.0))
                for i, (rgb, vertices, faces) in enumerate(tint):
                    mesh = self.client.scene.add_mesh_simple(
                        f"{OVERLAY}/tint{i}", vertices, faces, color=rgb, side="double",
                        cast_shadow=False, receive_shadow=False,
                    )  # fmt: skip
                    self._floor.append(mesh)
                if tint and grid is not None:
                    self._floor.append(
                        self.client.scene.add_line_segments(
                            f"{OVERLAY}/tint_grid", grid, GRID_RGB, thickness=1.5, thickness_units="screen"
                        )
                    )
            self._floor_key = key

    def _lines(self, name: str, points: np.ndarray, rgb: tuple[int, int, int], px: float) -> viser.LineSegmentsHandle:
        if len(points) < 2:
            points = np.vstack([points, points])
        return self.client.scene.add_line_segments(
            f"{OVERLAY}/{name}", polyline(points), rgb, thickness=px, thickness_units="screen"
        )

    def show(self, position: float) -> None:
        """Pose the robot at a fractional frame and grow the trail up to it."""
        with self._lock:
            if self._mj is None or self._poser is None:
                return
            data = self._poser.pose(position)
            head = on_floor(data.xpos[self._tracked][None, :2])
            # a fixed number of points (frames + 1, padded with the head) keeps the node's shape,
            # so each tick sends only new points
            done = np.vstack([self._trail_xyz[: int(position) + 1], head])
            done = np.vstack([done, np.repeat(head, len(self._trail_xyz) + 1 - len(done), axis=0)])
            with self.client.atomic():
                if self._trail is None:
                    self._trail = self._lines("trail", done, TRAIL_RGB, 4.0)
                else:
                    self._trail.points = polyline(done).astype(np.float32)
                self._mj.update_from_mjdata(data)

    def hide(self) -> None:
        """No robot on screen (waiting or error screens)."""
        with self._lock:
            self._poser = None
            self.client.scene.set_global_visibility(False)
