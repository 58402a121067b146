"""Pictures of a physics run: a strip of frames rendered from the MuJoCo plant offscreen.

``wmm-qp experiment circle|push --physics mujoco --frames DIR`` renders the plant's scene at
``FRAMES`` evenly spaced moments of the run (push: of each push phase) with MuJoCo's offscreen
renderer and writes them side by side as one PNG (``frames_circle.png``, ``frames_push_with_dm.png``,
``frames_push_without_dm.png``). Without a screen set ``MUJOCO_GL=osmesa`` (Debian:
``apt-get install libosmesa6``, and ``pip install PyOpenGL``) or ``MUJOCO_GL=egl``.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

FRAMES = 5  # frames in a strip
SIZE = (320, 400)  # [px] height, width of one frame


class Strip:
    """Renders the sim's physics plant at evenly spaced sim times (an ``observe`` callback).

    Args:
        span: [s] the frames cover this long from the first tick observed.
        frames: how many frames.
        distance, azimuth, elevation: the camera [m, deg, deg] (MuJoCo's free camera; 90 deg:
            from the robot's left side), looking at a point between the base and the EE of the
            first frame, fixed from then on (the motion shows against it).
    """

    def __init__(self, span: float, frames: int = FRAMES, distance: float = 2.8,
                 azimuth: float = 90.0, elevation: float = -10.0) -> None:
        self.offsets = list(np.linspace(0.0, 0.999 * span, frames))  # the last within the run
        self.t0: float | None = None
        self.images: list[np.ndarray] = []
        self.labels: list[str] = []
        self.camera = (distance, azimuth, elevation)
        self.lookat: np.ndarray | None = None

    def __call__(self, sim: Any) -> None:
        t = sim.state().t
        if self.t0 is None:
            self.t0 = t
        if not self.offsets or t + 1e-9 < self.t0 + self.offsets[0]:
            return
        self.offsets.pop(0)
        self.images.append(self.render(sim))
        st = sim.state()
        box = "" if math.isnan(st.box_displacement) else f", box {st.box_displacement * 100:.1f} cm"
        self.labels.append(f"t = {st.t:.1f} s{box}")

    def render(self, sim: Any) -> np.ndarray:
        """The plant's scene now, as an RGB image: the robot blue, the box orange and see-through
        (the arm behind it shows), the floor grey."""
        import mujoco

        plant = sim.plant
        model, data = plant.robot.model, plant.data
        st = sim.state()
        if self.lookat is None:
            self.lookat = np.array([0.5 * (st.base_true[0] + st.ee_true[0]), st.ee_true[1], 0.6 * st.ee_true[2]])
        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = self.lookat
        cam.distance, cam.azimuth, cam.elevation = self.camera
        with mujoco.Renderer(model, *SIZE) as r:
            r.update_scene(data, camera=cam)
            scene = r.scene
            for i in range(scene.ngeom):  # colours of this picture only (the model is untouched)
                g = scene.geoms[i]
                if g.objtype != mujoco.mjtObj.mjOBJ_GEOM:
                    continue
                if g.objid == plant.robot.box_geom:
                    g.rgba[:] = (0.9, 0.5, 0.1, 0.55)
                elif model.geom_bodyid[g.objid] == 0:
                    g.rgba[:] = (0.55, 0.6, 0.65, 1.0)
                else:
                    g.rgba[:] = (0.25, 0.45, 0.8, 1.0)
            for j in range(scene.nlight):  # brighter than the default headlight
                scene.lights[j].ambient[:] = (0.45, 0.45, 0.45)
                scene.lights[j].diffuse[:] = (0.7, 0.7, 0.7)
            return r.render().copy()

    def save(self, path: Path, title: str) -> Path:
        """The frames side by side, labelled, as one PNG."""
        from wmm_qp_tools.experiments.plots import _plt

        plt = _plt()
        n = len(self.images)
        fig, axes = plt.subplots(1, n, figsize=(3.2 * n, 3.0), squeeze=False)
        for ax, img, label in zip(axes[0], self.images, self.labels, strict=True):
            ax.imshow(img)
            ax.set_title(label, fontsize=9)
            ax.axis("off")
        fig.suptitle(title, fontsize=10)
        fig.tight_layout()
        fig.savefig(path, dpi=80)
        plt.close(fig)
        return path
