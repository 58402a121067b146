"""Everything an experiment's run needs: the robot, the controller and its config, the sim's
config (:func:`make_setup` loads and builds them)."""

from __future__ import annotations

from dataclasses import dataclass

from wmm_qp_sim import SimConfig

import wmm_qp
from wmm_qp.config import FloatArray
from wmm_qp.scene import Scene


@dataclass
class Setup:
    """Everything a run needs.

    Attributes:
        model: kinematic model (its ``config`` is the robot).
        controller: a controller made by :func:`wmm_qp.make_controller`.
        ctl_cfg: the controller's config (rate, gains).
        sim_cfg: the sim's config.
        seed: slip/drift seed.
        scene: obstacles and fence: the qp controller's collision rows keep the robot clear of
            them, the sim's collision referee checks them (None: no obstacles, no fence).
    """

    model: wmm_qp.WmmModel
    controller: wmm_qp.Controller
    ctl_cfg: wmm_qp.ControllerConfig
    sim_cfg: SimConfig
    seed: int | None = None
    scene: Scene | None = None

    @property
    def robot(self) -> wmm_qp.RobotConfig:
        """The robot description the run drives."""
        return self.model.config

    @property
    def W(self) -> FloatArray:
        """W of eq. (8) for this robot (the controller config's, else the robot's default)."""
        return self.ctl_cfg.weights_for(self.robot)


def make_setup(
    controller: str,
    solver: str | None = None,
    *,
    slip: bool = True,
    seed: int | None = None,
    robot: wmm_qp.RobotConfig | None = None,
    ctl_cfg: wmm_qp.ControllerConfig | None = None,
    wheel_units: str = "rad",
    scene: Scene | None = None,
    physics: str | None = None,
) -> Setup:
    """Load the configs and build the model, the controller and the sim config.

    Args:
        controller: "traditional", "paper" or "qp".
        solver: QP backend name (qp only); None = the config's.
        slip: base slip/drift on (the sim config's values) or off.
        seed: slip seed; None = the sim config's.
        robot: the robot description; None = the default robot file (the Gen3).
        ctl_cfg: the controller config; None = the default controller config.
        wheel_units: the traditional controller's J⁺ units, "rad" or "rim" (controllers/traditional.py).
        scene: obstacles and fence (``--scene``), given to the controller (its collision rows, when
            its config has them on) and to the sim's referee; None: none.
        physics: the sim's plant, "kinematic" or "mujoco"; None: the sim config's ``[physics] plant``.
    """
    from wmm_qp_sim import load_sim_config

    robot = wmm_qp.load_robot_config() if robot is None else robot
    model = wmm_qp.WmmModel(robot)
    cfg = wmm_qp.load_controller_config() if ctl_cfg is None else ctl_cfg
    cfg.weights_for(robot)  # a W of another length than the robot's: the config error, now
    if solver is not None:
        cfg = cfg.with_(qp={"solver": solver})
    if controller == "traditional":
        from wmm_qp.controllers.traditional import TraditionalController

        ctl: wmm_qp.Controller = TraditionalController(model, cfg, wheel_units=wheel_units)
    else:
        ctl = wmm_qp.make_controller(controller, model, cfg)
    # firmware off: the experiments measure the controllers, so the referee must see what a
    # controller commands without the robot's own protective stop masking it
    sim_cfg = load_sim_config().with_(firmware=False)
    if not slip:
        sim_cfg = sim_cfg.with_(slip={"enabled": False})
    if physics is not None:
        sim_cfg = sim_cfg.with_(physics={"plant": physics})
    if scene is not None:
        ctl.set_scene(scene)
    return Setup(model=model, controller=ctl, ctl_cfg=cfg, sim_cfg=sim_cfg, seed=seed, scene=scene)
