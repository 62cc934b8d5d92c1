"""How plans are executed in physics: the plant's step and contact model, the arm's and fingers'
gains, and the gripper's timing (`ExecutionConfig`, shared by the plant, the command stream and
the execution jobs)."""

from __future__ import annotations

import dataclasses

CONTACT_MODELS = ("point", "hydroelastic_with_fallback")
CONTACT_APPROXIMATIONS = ("lagged", "sap", "similar")


@dataclasses.dataclass(frozen=True)
class ExecutionConfig:
    """How the plans are executed.

    Attributes:
        time_step_s: the plant's discrete step. 2 ms resolves the fingers closing at 0.1 m/s
            (0.2 mm per step) and the cans' free fall into the bin, and keeps SAP well conditioned.
        contact_model: Drake contact model ("point" or "hydroelastic_with_fallback").
        contact_approximation: Drake discrete contact approximation ("lagged", "sap", "similar").
        arm_bandwidth_rad_s: natural frequency of each arm joint's PD loop (kp = M_ii w^2,
            kd = 2 zeta M_ii w, with M_ii the joint's inertia at the start configuration).
        damping_ratio: zeta above.
        grip_force_n: force limit of each finger while closing or holding (the WSG 50 grips
            with up to 80 N).
        finger_kp_n_m: finger position gain (N/m); the force saturates at grip_force_n.
        finger_kd_n_s_m: finger velocity gain (N s/m).
        close_s: time to close the gripper on the can before lifting.
        open_s: time to open the gripper over the bin before returning.
        settle_s: simulated time after the last motion before the cans are counted.
        publish_hz: frame rate of a Meshcat recording.
    """

    time_step_s: float = 0.002
    contact_model: str = "hydroelastic_with_fallback"
    contact_approximation: str = "lagged"
    hydroelastic_modulus_pa: float = 5e6
    hydroelastic_resolution_m: float = 0.01
    arm_bandwidth_rad_s: float = 30.0
    damping_ratio: float = 1.0
    grip_force_n: float = 40.0
    finger_kp_n_m: float = 2000.0
    finger_kd_n_s_m: float = 40.0
    close_s: float = 0.6
    open_s: float = 0.5
    settle_s: float = 1.0
    publish_hz: float = 30.0
