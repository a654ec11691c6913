"""Interactive runs: the same 1 ms loop as `engine.simulate`, drawn in MuJoCo's passive viewer.

The camera looks straight down on the planar arm, framed on it; the scenario runs at real time
and then holds its last state until the window is closed. Keys: space pauses and resumes,
Backspace or R restarts the scenario. The window is closed, and its thread joined, before the
interpreter exits (GLFW is terminated at exit: a render thread still running then crashes).
"""
from __future__ import annotations

import contextlib
import math
import threading
import time

import mujoco
import mujoco.viewer
import numpy as np

from .engine import ControlLoop
from .model import ConfigError
from .params import CONTROL_PERIOD

FRAME_EVERY = 16  # control periods between redraws (~60 frames per second)
HOLD_FRAME_S = 1 / 30  # s between redraws while paused or holding the end
KEY_SPACE, KEY_BACKSPACE, KEY_R = 32, 259, 82  # GLFW key codes


def check_display() -> None:
    """ConfigError (one line) unless GLFW can open the display: before any window or thread."""
    import glfw

    messages = []
    glfw.set_error_callback(lambda code, text: messages.append(text.decode() if isinstance(text, bytes) else str(text)))
    try:
        ok = glfw.init()
    finally:
        glfw.set_error_callback(None)
    if not ok:
        cause = messages[-1] if messages else "glfw.init failed"
        raise ConfigError(f"cannot open the display for the viewer ({cause}); "
                          "use 'watflex-sim run ... --rrd' headless")


def frame_top_down(cam: mujoco.MjvCamera, model: mujoco.MjModel, points: np.ndarray, margin: float = 1.3) -> None:
    """Point a free camera straight down (-z) at the bounding box of `points` (m), filling the view."""
    low, high = points[:, :2].min(axis=0), points[:, :2].max(axis=0)
    span = max(float(np.max(high - low)), 0.2) * margin
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = [*(low + high) / 2, float(points[:, 2].mean())]
    cam.distance = span / (2 * math.tan(math.radians(model.vis.global_.fovy) / 2))
    cam.elevation, cam.azimuth = -90.0, 90.0  # x to the right, y up on screen


def add_table(scene: mujoco.MjvScene, points: np.ndarray, size: float = 3.0) -> None:
    """A grey tabletop (visual only, `size` m square) under the arm in the viewer's user scene."""
    if scene is None or scene.ngeom >= scene.maxgeom:
        return
    centre = [*points[:, :2].mean(axis=0), float(points[:, 2].min()) - 0.06]
    mujoco.mjv_initGeom(scene.geoms[scene.ngeom], mujoco.mjtGeom.mjGEOM_BOX, np.array([size / 2, size / 2, 0.01]),
                        np.array(centre, dtype=float), np.eye(3).ravel(), np.array([0.3, 0.32, 0.35, 1.0], np.float32))
    table = scene.geoms[scene.ngeom]
    table.specular = table.shininess = table.reflectance = 0.0  # matte: the headlight does not wash it out
    scene.ngeom += 1


def view(scenario: dict, exit_after_s: float | None = None) -> None:
    """Run `scenario` at real time in the passive viewer, then hold its end until the window is
    closed (or `exit_after_s` s of wall time have passed). Raises SimulationError on divergence."""
    loop = ControlLoop(scenario)
    shown = mujoco.MjData(loop.model)  # what the window draws: a copy, so a restart can swap the loop
    mujoco.mj_copyData(shown, loop.model, loop.data)
    keys = {"pause": False, "restart": False}

    def on_key(code: int) -> None:
        if code == KEY_SPACE:
            keys["pause"] = not keys["pause"]
        elif code in (KEY_BACKSPACE, KEY_R):
            keys["restart"] = True

    before = set(threading.enumerate())
    handle = mujoco.viewer.launch_passive(loop.model, shown, key_callback=on_key,
                                          show_left_ui=False, show_right_ui=False)
    viewer_threads = [t for t in threading.enumerate() if t not in before]
    opened = time.perf_counter()
    try:
        with handle.lock():
            frame_top_down(handle.cam, loop.model, loop.rig.arm_points())
            add_table(handle.user_scn, loop.rig.arm_points())
        with contextlib.ExitStack() as stack:
            stack.enter_context(loop)
            k, start = 0, time.perf_counter()
            while handle.is_running():
                if exit_after_s is not None and time.perf_counter() - opened > exit_after_s:
                    break
                if keys["restart"]:
                    keys["restart"] = False
                    stack.close()
                    loop = ControlLoop(scenario)
                    stack.enter_context(loop)
                    k, start = 0, time.perf_counter()
                if keys["pause"] or k >= loop.n_ticks:  # hold: redraw, let the clock slide
                    mujoco.mj_copyData(shown, loop.model, loop.data)
                    handle.sync()
                    time.sleep(HOLD_FRAME_S)
                    start += HOLD_FRAME_S if keys["pause"] else 0.0
                    continue
                loop.tick(k)
                k += 1
                if k % FRAME_EVERY == 0 or k == loop.n_ticks:
                    mujoco.mj_copyData(shown, loop.model, loop.data)
                    handle.sync()
                    lag = k * CONTROL_PERIOD - (time.perf_counter() - start)
                    if lag > 0:
                        time.sleep(lag)
    finally:
        handle.close()
        for thread in viewer_threads:  # the window is gone before GLFW is terminated at exit
            thread.join(timeout=5.0)
