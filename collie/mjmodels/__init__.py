"""The MuJoCo model of every collie env, built without the envs: MJCF files shipped here (point,
car), Gymnasium's (ant, half_cheetah) and dm_control's (quadruped, humanoid, edited in memory),
compiled quietly, scenery drawn in (the car's hazards, the pixel envs' position-coloured floor).

numpy + mujoco only (Gymnasium and dm_control are read for their model files, when installed):
the trainer's envs simulate these models and the labeling UI replays them, so both build one
model. Names are the env names of trainer.envs.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

import mujoco

from collie.env_names import ENV_NAMES
from collie.mjmodels.floor import add_floor_material, paint_floor
from collie.mjmodels.quiet import quiet_compile
from collie.tasks import HAZARD_RADIUS, hazard_layout

HERE = Path(__file__).parent
MODEL_NAMES: tuple[str, ...] = ENV_NAMES
GYMNASIUM_FILES = {"ant": "ant.xml", "half_cheetah": "half_cheetah.xml"}
PIXEL_CAMERA = "pixels"  # the tracking camera the pixel envs observe through
# (behind, above) the centre of mass, metres, of each pixel env's camera
CAMERA_OFFSETS = {"quadruped": (2.5, 4.0), "humanoid": (3.0, 4.0)}
_PIXEL_XML: dict[str, str] = {}


def _known(name: str) -> None:
    if name not in MODEL_NAMES:
        raise ValueError(f"unknown env {name!r}; valid names: {', '.join(MODEL_NAMES)}")


def gymnasium_asset(filename: str) -> Path:
    """Path of an MJCF file bundled with Gymnasium, found without importing Gymnasium."""
    spec = importlib.util.find_spec("gymnasium")
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError("gymnasium is not installed (pip install 'gymnasium[mujoco]')")
    return Path(next(iter(spec.submodule_search_locations))) / "envs" / "mujoco" / "assets" / filename


def mjcf_path(name: str) -> Path:
    """The MJCF file env `name` is built from. The pixel envs edit dm_control's files in memory and
    have none: use model_xml / load_model."""
    _known(name)
    if name in GYMNASIUM_FILES:
        return gymnasium_asset(GYMNASIUM_FILES[name])
    if name in CAMERA_OFFSETS:
        raise ValueError(f"{name}: the model is edited in memory; use model_xml() or load_model()")
    return HERE / f"{name}.xml"


def add_hazards(spec: mujoco.MjSpec, centres: Any) -> None:
    """Draw hazards as flat, non-colliding discs on the floor (for 3-D views; physics ignores them)."""
    for i, (x, y) in enumerate(centres):
        spec.worldbody.add_geom(
            name=f"hazard{i}",
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[HAZARD_RADIUS, 0.001, 0],
            pos=[x, y, 0.001],
            contype=0,
            conaffinity=0,
            material="hazard",
        )


def dm_control_model(name: str) -> tuple[str, dict[str, Any]]:
    """dm_control's MJCF text of the robot on an empty floor, and its asset files."""
    if name == "quadruped":
        from dm_control.suite import common, quadruped

        return quadruped.make_model(floor_size=1.0).decode(), common.ASSETS  # floor resized below
    from dm_control.suite import humanoid

    xml, assets = humanoid.get_model_and_assets()
    return xml.decode() if isinstance(xml, bytes) else xml, assets


def _pixel_xml(name: str) -> str:
    """dm_control's robot with the position-coloured floor material and a camera that follows the
    centre of mass from behind and above."""
    if name not in _PIXEL_XML:
        xml, assets = dm_control_model(name)
        spec = mujoco.MjSpec.from_string(xml, assets)
        add_floor_material(spec, "floor")
        behind, above = CAMERA_OFFSETS[name]
        spec.worldbody.add_camera(
            name=PIXEL_CAMERA,
            mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM,
            pos=[0.0, -behind, above],
            xyaxes=[1, 0, 0, 0, above, behind],
        )
        with quiet_compile():
            spec.compile()  # to_xml needs a compiled spec
        _PIXEL_XML[name] = spec.to_xml()
    return _PIXEL_XML[name]


def model_xml(name: str, layout_seed: int | None = None) -> str:
    """Self-contained MJCF text of env `name` (`mujoco.MjModel.from_xml_string` compiles it); with
    `layout_seed`, random scenery (the car's hazards) is drawn in too (other envs ignore it)."""
    _known(name)
    if name in CAMERA_OFFSETS:
        return _pixel_xml(name)
    path = mjcf_path(name)
    if name != "car" or layout_seed is None:
        return path.read_text()
    spec = mujoco.MjSpec.from_file(str(path))
    add_hazards(spec, hazard_layout(layout_seed))
    spec.compile()  # to_xml needs a compiled spec
    return spec.to_xml()


def load_model(name: str, layout_seed: int | None = None) -> mujoco.MjModel:
    """The compiled model of env `name`, exactly as the env simulates (and renders) it, compiled
    quietly; pixel envs come with their floor painted in."""
    _known(name)
    with quiet_compile():
        if name in GYMNASIUM_FILES or name == "point":
            model = mujoco.MjModel.from_xml_path(str(mjcf_path(name)))  # relative includes resolve
        else:
            model = mujoco.MjModel.from_xml_string(model_xml(name, layout_seed))
    if name in CAMERA_OFFSETS:
        paint_floor(model)
    return model
