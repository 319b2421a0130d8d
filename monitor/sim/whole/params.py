"""The whole machine's parameters: config/excavator4_sim.yaml read strictly, converted to SI
and packed into the kernel's parameter vector."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from monitor.errors import ConfigError
from monitor.resources import resource_path
from monitor.schema.sections import key_text, shown, value
from monitor.schema.yamlfile import read_yaml
from monitor.sim.machine import BAR, LPM
from monitor.sim.whole import kernel as K

CYLINDERS = ("boom", "stick", "bucket")
_CYL_KEYS = {
    "bore_mm": (10, 300),
    "rod_mm": (5, 250),
    "stroke_mm": (10, 500),  # the DBC's RodPos range
    "dead_volume_l": (0.01, 20),
    "moment_arm_mm": (10, 2000),
    "angle_retracted_deg": (-180, 180),
    "link_mm": (50, 10000),
    "mass_kg": (1, 1e4),
    "viscous_friction_n_s_per_m": (0, 1e6),
}
# section -> key -> (lower, upper bound) in the YAML's units; every key is required.
_KEYS: dict[str, dict[str, tuple[float, float]]] = {
    "oil": {"density_kg_m3": (700, 1100), "bulk_modulus_gpa": (0.1, 3.0)},
    "pump": {
        "displacement_cc_rev": (0.5, 500),
        "engine_rpm": (500, 4000),
        "ls_margin_bar": (5, 60),
        "ls_band_bar": (0.5, 50),
        "cutoff_start_bar": (10, 500),
        "cutoff_full_bar": (10, 500),
        "line_volume_l": (0.01, 50),
        "leakage_cc_min_per_bar": (0.01, 1000),
        "relief_crack_bar": (10, 500),
        "relief_full_bar": (10, 600),
    },
    "valve": {
        "laminar_dp_bar": (0.01, 5),
        "tank_bar": (0, 20),
        "ls_line_volume_l": (0.001, 5),
        "ls_bleed_cc_min_per_bar": (0.01, 1000),
        **{f"{loop}_rated_flow_lpm": (0.1, 1000) for loop in K.LOOPS},
    },
    **{name: _CYL_KEYS for name in CYLINDERS},
    "swing": {
        "motor_displacement_cc_rev": (1, 2000),
        "gear_ratio": (1, 1000),
        "house_mass_kg": (10, 1e5),
        "house_radius_of_gyration_m": (0.05, 10),
        "attachment_inertia_kg_m2": (0, 1e6),
        "line_volume_l": (0.01, 20),
        "crossover_relief_crack_bar": (10, 500),
        "crossover_relief_full_bar": (10, 600),
        "motor_leakage_cc_min_per_bar": (0, 1000),
        "viscous_friction_n_m_s": (0, 1e6),
    },
    "solver": {"step_us": (5, 1000)},
}
GRAVITY_M_S2 = 9.81
#: A laminar conductance given in cc/min per bar, in m^3/s per Pa.
CC_MIN_PER_BAR = 1e-6 / 60.0 / BAR
#: Smoothing speed of the digging force's sign (m/s): slow enough for the RK4 step.
DIG_SMOOTHING_M_S = 0.01


@dataclass(frozen=True)
class WholeMachine:
    """The whole machine's values as read (YAML units), with SI views the simulator needs."""

    values: dict[str, dict[str, float]]
    source: str

    def __getitem__(self, section: str) -> dict[str, float]:
        return self.values[section]

    @property
    def step_s(self) -> float:
        return self.values["solver"]["step_us"] * 1e-6

    def area_a_m2(self, loop: str) -> float:
        return math.pi / 4 * (self.values[loop]["bore_mm"] * 1e-3) ** 2

    def area_b_m2(self, loop: str) -> float:
        c = self.values[loop]
        return math.pi / 4 * ((c["bore_mm"] * 1e-3) ** 2 - (c["rod_mm"] * 1e-3) ** 2)

    def stroke_m(self, loop: str) -> float:
        return self.values[loop]["stroke_mm"] * 1e-3

    @property
    def pump_flow_max_m3_s(self) -> float:
        p = self.values["pump"]
        return p["displacement_cc_rev"] * 1e-6 * p["engine_rpm"] / 60.0

    @property
    def swing_disp_m3_rad(self) -> float:
        """The motor's displacement seen at the house (through the slew gear), per radian."""
        s = self.values["swing"]
        return s["motor_displacement_cc_rev"] * 1e-6 * s["gear_ratio"] / (2 * math.pi)

    @property
    def house_inertia_kg_m2(self) -> float:
        s = self.values["swing"]
        return (
            s["house_mass_kg"] * s["house_radius_of_gyration_m"] ** 2
            + s["attachment_inertia_kg_m2"]
        )

    def rated_flow_m3_s(self, loop: str) -> float:
        return self.values["valve"][f"{loop}_rated_flow_lpm"] * LPM


def machine_from_mapping(data: Any, source: str = "<config>") -> WholeMachine:
    """Validate a parsed whole-machine YAML: every section and key known, present, in range."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping of sections, got {type(data).__name__}")
    values: dict[str, dict[str, float]] = {}
    for section, content in data.items():
        if section not in _KEYS:
            raise ConfigError(
                f"{source}: unknown section {shown(section)}; known: {', '.join(_KEYS)}"
            )
        if not isinstance(content, dict):
            raise ConfigError(f"{source}: section {shown(section)} must be a mapping")
        values[section] = {}
        for key, raw in content.items():
            if key not in _KEYS[section]:
                raise ConfigError(
                    f"{source}: unknown key {section}.{key_text(key)}; "
                    f"known: {', '.join(_KEYS[section])}"
                )
            low, high = _KEYS[section][key]
            number = value("float", raw, f"{section}.{key}", source)
            if not low <= number <= high:
                raise ConfigError(f"{source}: {section}.{key} = {number} is outside {low}..{high}")
            values[section][key] = float(number)
    for section, keys in _KEYS.items():
        missing = [k for k in keys if k not in values.get(section, {})]
        if missing:
            raise ConfigError(f"{source}: {section} lacks {', '.join(missing)}")
    m = WholeMachine(values, source)
    for loop in CYLINDERS:
        if m[loop]["rod_mm"] >= m[loop]["bore_mm"]:
            raise ConfigError(f"{source}: {loop}.rod_mm must be smaller than {loop}.bore_mm")
    for sec, lo, hi in (
        ("pump", "cutoff_start_bar", "cutoff_full_bar"),
        ("pump", "relief_crack_bar", "relief_full_bar"),
        ("swing", "crossover_relief_crack_bar", "crossover_relief_full_bar"),
    ):
        if m[sec][hi] <= m[sec][lo]:
            raise ConfigError(f"{source}: {sec}.{hi} must exceed {sec}.{lo}")
    return m


def load_whole_machine(path: str | Path | None = None) -> WholeMachine:
    """Load the whole-machine config (default: the shipped config/excavator4_sim.yaml)."""
    path = Path(path) if path is not None else resource_path("config", "excavator4_sim.yaml")
    return machine_from_mapping(read_yaml(path, "simulator config") or {}, str(path))


def _chain(m: WholeMachine, x: dict[str, float]) -> list[tuple[float, float]]:
    """Joint positions (boom pivot at the origin, stick pivot, bucket pivot, tip) at rod
    positions ``x`` (m)."""
    pts = [(0.0, 0.0)]
    angle = 0.0
    for loop, sign in zip(CYLINDERS, (1.0, -1.0, -1.0), strict=True):
        c = m[loop]
        angle += math.radians(c["angle_retracted_deg"]) + sign * x[loop] / (
            c["moment_arm_mm"] * 1e-3
        )
        px, py = pts[-1]
        length = c["link_mm"] * 1e-3
        pts.append((px + length * math.cos(angle), py + length * math.sin(angle)))
    return pts


def equivalent_masses(m: WholeMachine) -> dict[str, float]:
    """Mass at each rod (kg): the links beyond the joint (uniform rods) about it, at mid
    stroke, over the moment arm squared.  The chain's coupling (one joint's acceleration
    loading another) is left out: each cylinder moves its own equivalent mass."""
    x = {loop: 0.5 * m.stroke_m(loop) for loop in CYLINDERS}
    pts = _chain(m, x)
    out = {}
    for j, loop in enumerate(CYLINDERS):
        jx, jy = pts[j]
        inertia = 0.0
        for k in range(j, 3):
            (ax, ay), (bx, by) = pts[k], pts[k + 1]
            mass = m[CYLINDERS[k]]["mass_kg"]
            length = math.hypot(bx - ax, by - ay)
            cx, cy = 0.5 * (ax + bx), 0.5 * (ay + by)
            inertia += mass * (length**2 / 12.0 + (cx - jx) ** 2 + (cy - jy) ** 2)
        out[loop] = inertia / (m[loop]["moment_arm_mm"] * 1e-3) ** 2
    return out


def pack_params(m: WholeMachine) -> np.ndarray:
    """The kernel's parameter vector (SI)."""
    prm = np.zeros(K.N_PARAMS)
    p, v, s = m["pump"], m["valve"], m["swing"]
    prm[K.BETA] = m["oil"]["bulk_modulus_gpa"] * 1e9
    prm[K.V_LINE] = p["line_volume_l"] * 1e-3
    prm[K.DISP_MAX] = p["displacement_cc_rev"] * 1e-6
    prm[K.LS_MARGIN] = p["ls_margin_bar"] * BAR
    prm[K.LS_BAND] = p["ls_band_bar"] * BAR
    prm[K.PUMP_LEAK] = p["leakage_cc_min_per_bar"] * CC_MIN_PER_BAR
    prm[K.V_LS] = v["ls_line_volume_l"] * 1e-3
    prm[K.LS_BLEED] = v["ls_bleed_cc_min_per_bar"] * CC_MIN_PER_BAR
    prm[K.CUT_START] = p["cutoff_start_bar"] * BAR
    prm[K.CUT_FULL] = p["cutoff_full_bar"] * BAR
    prm[K.RELIEF_CRACK] = p["relief_crack_bar"] * BAR
    prm[K.RELIEF_GAIN] = m.pump_flow_max_m3_s / (
        (p["relief_full_bar"] - p["relief_crack_bar"]) * BAR
    )
    prm[K.DP_LAM] = v["laminar_dp_bar"] * BAR
    prm[K.PTANK] = v["tank_bar"] * BAR
    prm[K.GRAV] = GRAVITY_M_S2
    prm[K.XR_CRACK] = s["crossover_relief_crack_bar"] * BAR
    prm[K.XR_GAIN] = m.rated_flow_m3_s("swing") / (
        (s["crossover_relief_full_bar"] - s["crossover_relief_crack_bar"]) * BAR
    )
    prm[K.MOTOR_LEAK] = s["motor_leakage_cc_min_per_bar"] * CC_MIN_PER_BAR
    prm[K.V_EPS_DIG] = DIG_SMOOTHING_M_S
    for i, loop in enumerate(CYLINDERS):
        c = m[loop]
        prm[(K.L1, K.L2, K.L3)[i]] = c["link_mm"] * 1e-3
        prm[(K.M1, K.M2, K.M3)[i]] = c["mass_kg"]
        prm[(K.R1, K.R2, K.R3)[i]] = c["moment_arm_mm"] * 1e-3
        prm[(K.A1, K.A2, K.A3)[i]] = math.radians(c["angle_retracted_deg"])
    masses = equivalent_masses(m)
    margin = p["ls_margin_bar"] * BAR
    for j, loop in enumerate(K.LOOPS):
        b = K.LOOP0 + K.NL * j
        # Kv: the rated flow at full stroke through the margin's drop.
        prm[b + K.P_KV] = m.rated_flow_m3_s(loop) / math.sqrt(margin)
        if loop == "swing":
            prm[b + K.P_AA] = prm[b + K.P_AB] = m.swing_disp_m3_rad
            prm[b + K.P_V0A] = prm[b + K.P_V0B] = s["line_volume_l"] * 1e-3
            prm[b + K.P_MASS] = m.house_inertia_kg_m2
            prm[b + K.P_CVISC] = s["viscous_friction_n_m_s"]
            prm[b + K.P_STROKE] = 0.0
        else:
            c = m[loop]
            prm[b + K.P_AA] = m.area_a_m2(loop)
            prm[b + K.P_AB] = m.area_b_m2(loop)
            prm[b + K.P_STROKE] = m.stroke_m(loop)
            prm[b + K.P_V0A] = prm[b + K.P_V0B] = c["dead_volume_l"] * 1e-3
            prm[b + K.P_MASS] = masses[loop]
            prm[b + K.P_CVISC] = c["viscous_friction_n_s_per_m"]
    return prm
