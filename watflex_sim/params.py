"""Every rig parameter, once, with its unit and its source.

The models in `models/` are generated from these values by `tools/build_models.py`;
nothing else in the project restates a number of the datasheet (`shared/spec/rigs.md`).
Values marked [choice] are the datasheet's own choices where the sources leave a gap;
values marked [ours] are this project's modelling choices, measured in the README.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

GRAVITY = 9.81  # m/s^2 [ours: standard value, used for the air-bearing load]
CONTROL_PERIOD = 1e-3  # s; rigs.md §1 "control period 1 ms", thesis 2.4 (1 ms sampling)
# Joint dry friction as MuJoCo's frictionloss constraint, made nearly hard [ours]: creep
# < 1e-6 rad in 10 s at 0.9 x break-away (tests/test_joint_friction.py).
STICK_SOLREF = (0.001, 1.0)  # (time constant s, damping ratio): as hard as 0.5 ms steps allow
STICK_SOLIMP = (0.9999, 0.9999, 0.001, 0.5, 2.0)  # (d0, dwidth, width m, midpoint, power)


@dataclass(frozen=True)
class Beam:
    """A uniform flexible beam bending in the plane of motion."""

    length: float  # m, flexible part only
    EI: float  # N m^2, bending stiffness
    mass_per_length: float  # kg/m
    thickness: float  # m, in the bending direction (strain = -(t/2) w'')
    height: float  # m, out of the plane (drawing only)
    tip_mass_for_damping: float  # kg, point mass used to place the first mode for beta [ours]
    damping_ratio: float = 0.01  # rigs.md §1, §2: modal damping ratio 0.01 [choice]
    tip_offset_for_damping: float = 0.0  # m, that mass's rigid arm beyond the beam's end (Watflex: l1c, l2c)

    @property
    def first_mode_rad_s(self) -> float:
        """Clamped-free first bending mode with `tip_mass_for_damping` on its arm beyond the tip (rad/s)."""
        from .beam_theory import clamped_free_frequencies

        return clamped_free_frequencies(self, self.tip_mass_for_damping, 1, self.tip_offset_for_damping)[0]

    @property
    def damping_beta(self) -> float:
        """Stiffness-proportional damping c = beta k (s), giving `damping_ratio` on mode 1."""
        return 2.0 * self.damping_ratio / self.first_mode_rad_s


@dataclass(frozen=True)
class LaserArm:
    """rigs.md §1: single flexible link with a tip (laser spot) sensor."""

    beam: Beam = field(
        default_factory=lambda: Beam(
            length=1.18,  # m; rigs.md §1: paper table 2
            EI=8404.0,  # N m^2; rigs.md §1: paper table 2
            mass_per_length=0.75,  # kg/m; rigs.md §1: paper table 2
            thickness=0.01,  # m; [ours] drawing and strain only, no source gives it
            height=0.05,  # m; [ours] drawing only
            tip_mass_for_damping=0.15,  # kg; tip sensor, no payload [ours]
        )
    )
    tip_sensor_mass: float = 0.15  # kg at the tip; rigs.md §1: paper table 2
    arm_inertia: float = 0.639  # kg m^2 beam + tip sensor + hub; rigs.md §1: paper table 4
    arm_viscous: float = 0.222  # N m s/rad at the output; rigs.md §1: paper table 4
    torque_constant: float = 0.26  # N m/A motor side; rigs.md §1: paper table 1
    back_emf: float = 20.53  # V s/rad, referred to the hub speed; rigs.md §1: paper table 1
    gear_ratio: float = 80.0  # rigs.md §1 [choice: 20.53/0.26 ~ 79, nearest standard]
    gear_efficiency: float = 0.6  # output torque = eta N K_T i; rigs.md §1: paper section 2
    motor_inertia: float = 1.2e-4  # kg m^2 motor side; rigs.md §1: paper table 1
    motor_viscous: float = 1.4e-4  # N m s/rad motor side; rigs.md §1: paper table 1
    resistance: float = 3.4  # ohm; rigs.md §1: paper table 1
    current_limit: float = 1.9  # A; rigs.md §1: paper section 2
    voltage_limit: float = 24.0  # V; rigs.md §1 "Drive" [choice]
    sensor_gain: float = 3300.0  # V/m (3.3 V/mm); rigs.md §1: paper section 1.3
    sensor_limit: float = 10.0  # V; rigs.md §1: paper section 1.3
    encoder_step: float = 2 * math.pi / (4 * 1024 * 80)  # rad; rigs.md §1 [choice]
    noise_tip_sensor: float = 0.01  # V rms; rigs.md §3 [choice]
    noise_current: float = 0.004  # A rms; rigs.md §3 [choice]
    hub_radius: float = 0.05  # m [ours] drawing: the hub a solid disc carrying hub_inertia
    n_segments: int = 11  # [ours] README "Discretisation": 3 modes within 1 %
    timestep: float = 1e-4  # s [ours] README "Time step": stable with beta ~ 1e-4 s

    @property
    def hub_inertia(self) -> float:
        """Rigid hub inertia (kg m^2) = J_arm - rho L^3/3 - m_tip L^2; rigs.md §1 [choice: derived]."""
        b = self.beam
        return self.arm_inertia - b.mass_per_length * b.length**3 / 3 - self.tip_sensor_mass * b.length**2

    @property
    def reflected_motor_inertia(self) -> float:
        """N^2 J_e (kg m^2), rigs.md §1 (0.768)."""
        return self.gear_ratio**2 * self.motor_inertia

    @property
    def hub_viscous(self) -> float:
        """Arm bearing plus reflected motor viscous friction at the hub (N m s/rad)."""
        return self.arm_viscous + self.gear_ratio**2 * self.motor_viscous

    @property
    def torque_per_amp(self) -> float:
        """Output torque per armature current eta N K_T (N m/A), rigs.md §1 (12.48)."""
        return self.gear_efficiency * self.gear_ratio * self.torque_constant


@dataclass(frozen=True)
class Actuator:
    """A harmonic-drive joint actuator of the Watflex arm (thesis tables 4.1, A.1)."""

    gear_ratio: float  # -
    torque_constant: float  # N m/A, output side
    amplifier_gain: float  # A/V, current mode
    inertia: float  # kg m^2 at the output, identified with clamps and bearings
    mass: float  # kg
    dac_range: float = 10.0  # V, 12-bit converter over +-10 V; rigs.md §2 [choice]
    dac_bits: int = 12  # rigs.md §2 [choice]

    @property
    def torque_limit(self) -> float:
        """Torque at the converter's full range (N m), rigs.md §2 (65.8 / 53.8)."""
        return self.dac_range * self.amplifier_gain * self.torque_constant


@dataclass(frozen=True)
class Friction:
    """Exponential friction per direction, thesis eq. 4.5-4.6 with delta = 2 (rigs.md §2)."""

    alpha0: float  # N m, Coulomb level
    alpha1: float  # N m, Stribeck excess (break-away = alpha0 + alpha1)
    alpha2: float  # N m s/rad, viscous
    v_s: float  # rad/s, Stribeck velocity


ALU_E = 70e9  # Pa; rigs.md §2 [choice]
ALU_DENSITY = 2700.0  # kg/m^3; rigs.md §2 [choice]


def _alu_plate(length: float, thickness: float, height: float, tip_mass: float, tip_offset: float) -> Beam:
    """Aluminium plate on edge bending in the table plane (EI = E h t^3 / 12); `tip_mass` kg `tip_offset` m beyond
    its end places the first mode for the damping rule."""
    return Beam(
        length=length,
        EI=ALU_E * height * thickness**3 / 12.0,
        mass_per_length=ALU_DENSITY * thickness * height,
        thickness=thickness,
        height=height,
        tip_mass_for_damping=tip_mass,
        tip_offset_for_damping=tip_offset,
    )


L1C, L2C = 0.115, 0.083  # m, end clamp of link 1 -> elbow axis, of link 2 -> end-effector centre; rigs.md §2


@dataclass(frozen=True)
class Watflex:
    """rigs.md §2: two flexible links on air bearings, harmonic-drive joints."""

    # Geometry, m; rigs.md §2: thesis fig. 2.2 / 3.3 / 5.1
    l1a: float = 0.130  # shoulder axis -> root clamp of link 1 (rigid)
    l1c: float = L1C  # end clamp of link 1 -> elbow axis (rigid)
    l2a: float = 0.140  # elbow axis -> root clamp of link 2 (rigid)
    l2c: float = L2C  # end clamp of link 2 -> end-effector centre (rigid)
    # Links: 6.73 x 38.4 mm and 4.8 x 38.2 mm plates, 470 mm flexible; rigs.md §2.
    # tip_mass_for_damping [ours]: what each link carries at its tip in the elbow experiments
    # (link 2: the end effector; link 1: elbow actuator + link 2 + end effector), where it sits: at the end of the
    # rigid end clamp (link 2: the end effector's centre, rigs.md §2; link 1: the elbow axis). Since 2026-12-08: the
    # first mode was placed with the mass at the beam's end, 9.34 rad/s for link 2's 7.34, which put 0.0079 on it
    link1: Beam = field(default_factory=lambda: _alu_plate(0.470, 6.73e-3, 38.4e-3, 6.8 + 0.233 + 8.1, L1C))
    link2: Beam = field(default_factory=lambda: _alu_plate(0.470, 4.8e-3, 38.2e-3, 8.1, L2C))
    shoulder: Actuator = field(
        default_factory=lambda: Actuator(50, 13.3, 0.4948, 3.41, 11.8)  # rigs.md §2: tables 4.1, A.1
    )
    elbow: Actuator = field(
        default_factory=lambda: Actuator(50, 11.5, 0.4679, 1.25, 6.8)  # rigs.md §2: tables 4.1, A.1
    )
    end_effector_mass: float = 8.1  # kg point mass at the end of l2c; rigs.md §2 [choice]
    # Strain-gauge bridges: distance from the root of the flexible part (m) and
    # calibration K (strain per volt); rigs.md §2: thesis fig. 3.3, table 3.2.
    gauges: dict = field(
        default_factory=lambda: {
            "1A": (1, 0.0175, 2.034e-4),
            "1B": (1, 0.235, 1.997e-4),
            "1C": (1, 0.4525, 2.055e-4),
            "2A": (2, 0.0175, 2.017e-4),
            "2B": (2, 0.235, 1.974e-4),
        }
    )
    encoder_step: float = 2 * math.pi / 204800  # rad; rigs.md §2: 1024 x 4 x 50 counts/rev
    # Joint friction, rigs.md §2 table (thesis table 4.3): (positive, negative) direction.
    shoulder_friction: tuple = (Friction(7.9707, 1.4476, 4.9349, 0.0363), Friction(7.7538, 0.8626, 4.3267, 0.0221))
    elbow_friction: tuple = (Friction(4.9589, 0.5232, 1.2563, 0.0402), Friction(5.4392, 0.5556, 0.8162, 0.0208))
    noise_strain: float = 0.002  # V rms; rigs.md §3 [choice]
    strain_adc_range: float = 10.0  # V, 12-bit over +-10 V; rigs.md §3 [choice]
    camera_error: float = 0.003  # m, uniform +-; rigs.md §3 [choice]
    camera_rate: float = 25.0  # Hz; rigs.md §3 [choice]
    bearing_radius: float = 0.03  # m, contact sphere of each air bearing [ours]
    bearing_timeconst: float = 0.01  # s, contact solref time constant [ours]
    n_segments: int = 12  # per link [ours] README "Discretisation": 3 modes within 1 % even bare
    timestep: float = 5e-4  # s [ours] README "Time step"
    # Single-link set-up, rigs.md §2 (thesis 5.2.4: "the shoulder motor had to be fixed ... by
    # mounting a rigid link between shoulder and elbow actuator and a cross beam to the wall"):
    # a scenario or recording whose locked_joints name this joint is that set-up.
    single_link_lock: str = "shoulder"

    def single_link(self, locked_joints) -> bool:
        """True if `locked_joints` (joint -> rad) describe the single-link set-up (rigs.md §2)."""
        return self.single_link_lock in (locked_joints or {})

    def unmounted_channels(self, locked_joints) -> tuple[str, ...]:
        """Channels with no sensor in the set-up `locked_joints` describe: in the single-link set-up
        flexible link 1 is not mounted, so neither are its strain bridges (strain_1A/1B/1C)."""
        if not self.single_link(locked_joints):
            return ()
        return tuple(f"strain_{name}" for name, (link, _x, _k) in self.gauges.items() if link == 1)


@dataclass(frozen=True)
class Emps:
    """EMPS ball-screw drive (shared/realdata/emps/ABOUT.md, Janot et al. 2019), load side.

    The nominal model is a mass with viscous friction only (issue 5): rough datasheet-like
    values [ours], not the published estimates the diagnosis must find (M = 95.11 kg,
    Fv = 203.5 N s/m); the rig description lets the refit move them by +-25 %.
    """

    mass: float = 100.0  # kg [ours: nominal guess]
    viscous: float = 180.0  # N s/m [ours: nominal guess]
    drive_gain: float = 35.15065188  # N/V, `gtau` in the data files (ABOUT.md)
    command_limit: float = 10.0  # V, drive saturation in the authors' simulator (ABOUT.md)
    timestep: float = 5e-4  # s [ours]: 2 physics steps per 1 ms sample; dry friction sticks hard


LASER_ARM = LaserArm()
WATFLEX = Watflex()
EMPS = Emps()
RIGS = {"laser_arm": LASER_ARM, "watflex": WATFLEX, "emps": EMPS}
