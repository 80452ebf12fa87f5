#!/usr/bin/env python3
"""Side-by-side benchmark: this drive against motulator 0.5.0 on motulator's 2.2 kW machine.

Run through benches/peer/run.sh, which makes the venv. Each case is one function call that
builds a `Case`: the scenario TOML for our simulator (written to a temporary folder and run
with `$ACIM_SIM run FILE --out DIR -q`) and the matching motulator setup (its 0.5.0
sensorless current-vector control, `motulator.drive.control.im.CurrentVectorControl`).
Both plants are ideal (no dead time, no device drop, ideal current sensing, no noise, no
friction) and see the same speed reference (a ramp at the drive's 500 rpm/s from the same
instants) and the same load torque (a ramp is 10 equal steps). Every metric is computed by
`analyse` from the two time series: t, true speed, estimated speed, and whether the drive
still runs.

    python3 peer.py --ours-only     # our side only (standard library; no motulator)
    python peer.py                  # both sides (the venv's python), writes the page
    python peer.py --only step      # the cases whose name contains "step"; no page written
"""

import argparse
import concurrent.futures
import csv
import json
import math
import os
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
MACHINE_FILE = ROOT / "crates/acim-sim/machines/motulator-2k2.toml"
PAGE = ROOT / "docs/peer-benchmark.md"
FIGURES = ROOT / "docs/figures/peer"
SCRATCH = HERE / "out"

MACHINE = tomllib.loads(MACHINE_FILE.read_text())
NP = MACHINE["nameplate"]
IG = MACHINE["inverse_gamma"]
POLE_PAIRS = int(NP["pole_pairs"])
RATED_TORQUE = float(NP["torque_nm"])  # 14.6 N m, motulator's nominal torque
RATED_RPM = 60.0 * NP["frequency_hz"] / POLE_PAIRS  # 1500 rpm (synchronous)
INERTIA = float(MACHINE["plant"]["inertia_kgm2"])  # 0.015 kg m^2
DC_BUS = 540.0
# the drive's ramp from a nameplate: the rated speed in 3 s (acim::nameplate::RAMP_TIME)
RAMP_RPM_S = RATED_RPM / 3.0
# the current limit of both: 1.5 x the rated peak current (10.6 A)
CURRENT_LIMIT = 1.5 * math.sqrt(2.0) * NP["current_a"]

# timeline: our drive's start (offsets, magnetizing, inverter test) ends near 1.0 s; every
# reference step comes after it, at the same instant for both drives
T_REF = 1.2
HOLD_TOL_MOTORING = 5.0  # rpm: the project's drift threshold
# our --set overrides for every case (environment PEER_SETS, space-separated), e.g.
# PEER_SETS="drive.loops.control_period_s=1e-4" to benchmark another setting
EXTRA_SETS = os.environ.get("PEER_SETS", "").split()
# our runs with the paper's observer (the default from the nameplate is the flux observer)
PAPER_SETS = ["drive.observer=reduced"]
HOLD_TOL = 30.0  # rpm: regenerating loads and parameter errors


# ---------------------------------------------------------------------------------------
# the cases


@dataclass
class Case:
    """One scenario, for both drives."""

    name: str
    group: str
    label: str
    duration: float
    speed: list  # [(t_s, rpm)]: target steps, ramped at RAMP_RPM_S from each instant
    load: list = field(default_factory=list)  # [(t_s, N m)]: active load, positive brakes
    errors: dict = field(default_factory=dict)  # controller parameter factors: rs, rr, lm
    sets: list = field(default_factory=list)  # our --set overrides
    kind: str = "hold"  # which metrics: step, hold, reversal, ramp
    event: float = 0.0  # step / reversal instant; ramp start
    target: float = 0.0  # rpm the metrics hold against
    tol: float = HOLD_TOL
    ramp_end: float = 0.0

    def ref_rpm(self, t):
        """The speed reference at t: a ramp at RAMP_RPM_S towards each target in turn."""
        r, t_prev, goal = 0.0, 0.0, 0.0
        for ts, rpm in sorted(self.speed) + [(math.inf, None)]:
            t_end = min(ts, t)
            if t_end > t_prev:
                d = RAMP_RPM_S * (t_end - t_prev)
                r = min(goal, r + d) if goal >= r else max(goal, r - d)
            if ts >= t:
                return r
            t_prev, goal = ts, rpm
        return r

    def load_at(self, t):
        tau = 0.0
        for ts, v in sorted(self.load):
            if t >= ts:
                tau = v
        return tau

    # -- our side ---------------------------------------------------------------------
    def our_toml(self):
        plant = dict(MACHINE["plant"])
        plant["friction_nms"] = 0.0  # motulator's plant has none
        tables = [
            ("nameplate", MACHINE["nameplate"]),
            ("plant", plant),
            # the machine in inverse-Gamma form: with it the file reads as a machine file
            # (the controller gets the plant's data unless [controller] says otherwise)
            ("inverse_gamma", IG),
            ("board", {"dc_bus_v": DC_BUS, "current_full_scale_a": 20.0}),
            ("inverter", {"dead_time_s": 0.0, "device_drop_v": 0.0}),
            (
                "sensors",
                {
                    "noise_a": 0.0,
                    "gain_error": [0.0, 0.0, 0.0],
                    "offset_a": [0.0, 0.0, 0.0],
                    "full_scale_a": 20.0,
                    "adc_bits": 16,
                },
            ),
        ]
        if self.errors:
            e = self.errors
            lm = IG["l_m_h"] * e.get("lm", 1.0)
            # the inverse-Gamma model as a T-model with no rotor leakage
            tables.append(
                (
                    "controller",
                    {
                        "rs_ohm": IG["rs_ohm"] * e.get("rs", 1.0),
                        "rr_ohm": IG["rr_ohm"] * e.get("rr", 1.0),
                        "ls_h": IG["l_sigma_h"] + lm,
                        "lr_h": lm,
                        "lm_h": lm,
                        "pole_pairs": POLE_PAIRS,
                        "inertia_kgm2": INERTIA,
                        "friction_nms": 0.0,
                    },
                )
            )
        out = [
            "# generated by benches/peer/peer.py",
            f'name = "{self.name}"',
            f'description = "peer benchmark: {self.label}"',
            f"duration_s = {self.duration}",
            "seed = 1",
            "",
        ]
        for name, t in tables:
            out.append(f"[{name}]")
            out += [f"{k} = {toml_value(v)}" for k, v in t.items()]
            out.append("")
        for ts, rpm in self.speed:
            out += ["[[speed_profile]]", f"t_s = {ts}", f"rpm = {rpm}", ""]
        for ts, tau in self.load:
            out += ["[[load_profile]]", f"t_s = {ts:.4f}", 'kind = "active"', f"torque_nm = {tau:.5f}", ""]
        out += ["[[windows]]", 'name = "last-second"', f"from_s = {self.duration - 1.0}", f"to_s = {self.duration}", ""]
        return "\n".join(out)

    def run_ours(self, sim, tmp, extra=()):
        """Runs this case through our simulator in the directory `tmp` (its own per run: runs
        go in parallel); returns the series and the run's wall-clock time in seconds."""
        path = Path(tmp) / f"{self.name}.toml"
        path.write_text(self.our_toml())
        cmd = [sim, "run", str(path), "--out", str(tmp), "-q"]
        for s in self.sets + EXTRA_SETS + list(extra):
            cmd += ["--set", s]
        t0 = time.perf_counter()
        p = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        csv_path = Path(tmp) / f"{self.name}.csv"
        if p.returncode != 0 or not csv_path.exists():
            raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stderr}{p.stdout}")
        t, w, we, ref, limited = [], [], [], [], []
        state = fault = ""
        fault_t = None
        # the columns read by position (a DictReader per row took as long as the run)
        with open(csv_path, newline="") as f:
            rows = csv.reader(f)
            head = next(rows)
            it, iw, iwe, iref, ist, ifa, ilim = (head.index(k) for k in (
                "t_s", "speed_rpm", "speed_est_rpm", "speed_ref_rpm", "state_name",
                "fault_reason", "speed_target_limited"))
            for row in rows:
                t.append(float(row[it]))
                w.append(float(row[iw]))
                we.append(float(row[iwe]))
                ref.append(float(row[iref]))
                state = row[ist]
                if row[ifa] and not fault:
                    fault, fault_t = row[ifa], t[-1]
                limited.append(row[ilim] not in ("", "0"))
        return Series(t, w, we, running=(state == "running" and not fault), stop=fault or (state if state != "running" else ""), stop_t=fault_t, limited=limited, drive_ref=ref), wall

    # -- motulator's side -------------------------------------------------------------
    def run_motulator(self):
        import numpy as np
        from motulator.drive import model
        import motulator.drive.control.im as control
        from motulator.drive.utils import (
            BaseValues,
            InductionMachineInvGammaPars,
            InductionMachinePars,
            NominalValues,
        )

        nom = NominalValues(U=NP["voltage_v"], I=NP["current_a"], f=NP["frequency_hz"], P=NP["power_w"], tau=RATED_TORQUE)
        base = BaseValues.from_nominal(nom, n_p=POLE_PAIRS)
        true = InductionMachineInvGammaPars(n_p=POLE_PAIRS, R_s=IG["rs_ohm"], R_R=IG["rr_ohm"], L_sgm=IG["l_sigma_h"], L_M=IG["l_m_h"])
        e = self.errors
        est = InductionMachineInvGammaPars(
            n_p=POLE_PAIRS,
            R_s=IG["rs_ohm"] * e.get("rs", 1.0),
            R_R=IG["rr_ohm"] * e.get("rr", 1.0),
            L_sgm=IG["l_sigma_h"],
            L_M=IG["l_m_h"] * e.get("lm", 1.0),
        )
        machine = model.InductionMachine(InductionMachinePars.from_inv_gamma_model_pars(true))
        mechanics = model.StiffMechanicalSystem(J=INERTIA)  # B_L = 0: no friction
        converter = model.VoltageSourceConverter(u_dc=DC_BUS)
        mdl = model.Drive(converter, machine, mechanics)  # averaged PWM (zoh), one-sample delay
        # as motulator's 2.2 kW example: current limit 1.5 x the rated peak, nominal flux
        # from the rated voltage and frequency
        cfg = control.CurrentReferenceCfg(est, max_i_s=1.5 * base.i, nom_u_s=base.u, nom_w_s=base.w)
        assert abs(cfg.max_i_s - CURRENT_LIMIT) < 1e-9
        ctrl = control.CurrentVectorControl(est, cfg, J=INERTIA, T_s=250e-6, sensorless=True)
        k = POLE_PAIRS * 2.0 * math.pi / 60.0  # rpm -> electrical rad/s
        ctrl.ref.w_m = lambda t: k * self.ref_rpm(t)
        mdl.mechanics.tau_L = np.vectorize(self.load_at, otypes=[float])
        sim = model.Simulation(mdl, ctrl)
        t0 = time.perf_counter()
        sim.simulate(t_stop=self.duration)
        self.wall = time.perf_counter() - t0
        tc = np.asarray(ctrl.data.ref.t, dtype=float)
        w_est = np.real(np.asarray(ctrl.data.fbk.w_m, dtype=complex)) / k
        # the true speed at the sampling instants, from the solver's output
        tm = np.asarray(mdl.mechanics.data.t, dtype=float)
        wm = np.asarray(mdl.mechanics.data.w_M, dtype=float) * 60.0 / (2.0 * math.pi)
        tm, idx = np.unique(tm, return_index=True)
        w = np.interp(tc, tm, wm[idx])
        finite = bool(np.all(np.isfinite(w)) and np.all(np.isfinite(w_est)))
        ended = float(tc[-1]) if len(tc) else 0.0
        diverged = (not finite) or ended < self.duration - 0.01
        stop = f"diverged at {ended:.2f} s" if diverged else ""
        return Series(list(map(float, tc)), list(map(float, w)), list(map(float, w_est)), running=not diverged, stop=stop, stop_t=ended if diverged else None, limited=None, drive_ref=None)


@dataclass
class Series:
    """What the metrics see of one run."""

    t: list
    w: list  # true speed, rpm
    w_est: list  # estimated speed, rpm
    running: bool  # still in control at the end (ours: state running, no fault)
    stop: str  # fault reason or why not running ("" when running)
    stop_t: float
    limited: list  # ours, per sample: the drive reports its target limited (None: motulator)
    drive_ref: list  # ours: the drive's own (ramped) reference, for the consistency check


def toml_value(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(v)


def load_ramp(t0, ramp_s, torque, n=10):
    """A load ramped in over ramp_s from t0: n equal steps, the full torque at t0 + ramp_s."""
    return [(t0 + ramp_s * (k + 1) / n, torque * (k + 1) / n) for k in range(n)]


def rated_step(rpm, t_step, duration, limit=True):
    return Case(
        name=f"step-{rpm}" + ("" if limit else "-nolimit"),
        group="step",
        label=f"{rpm} rpm" + ("" if limit else ", the paper's observer's regeneration limit off"),
        duration=duration,
        speed=[(T_REF, float(rpm))],
        load=[(t_step, RATED_TORQUE)],
        sets=[] if limit else ["drive.loops.regen_min_frequency_hz=0"],
        kind="step",
        event=t_step,
        target=float(rpm),
    )


def cases_steps():
    """Rated-load steps at 750, 75 and 30 rpm (5 % and 2 % of base speed); at the low speeds
    also with our regeneration limit off (motulator's run is the same)."""
    return [
        rated_step(750, 3.5, 5.5),
        rated_step(75, 2.5, 5.0),
        rated_step(75, 2.5, 5.0, limit=False),
        rated_step(30, 2.5, 5.0),
        rated_step(30, 2.5, 5.0, limit=False),
    ]


def cases_motoring_ramps():
    out = []
    for rpm in (45, 30, 15, 0):
        out.append(
            Case(
                name=f"motoring-{rpm}",
                group="motoring",
                label=f"rated motoring load ramped in over 1 s at {rpm} rpm",
                duration=5.0,
                speed=[(T_REF, float(rpm))],
                load=load_ramp(2.0, 1.0, RATED_TORQUE),
                # a held zero target keeps the flux on (the default policy switches off)
                sets=["drive.zero_speed.policy=hold"] if rpm == 0 else [],
                target=float(rpm),
                tol=HOLD_TOL_MOTORING,
            )
        )
    return out


REGEN_FRACTIONS = (0.25, 0.5, 1.0)
REGEN_SPEEDS = (15, 30, 45, 60, 75)


def cases_regen():
    out = []
    for frac in REGEN_FRACTIONS:
        for rpm in REGEN_SPEEDS:
            for limit in (True, False):
                out.append(
                    Case(
                        name=f"regen-{int(frac * 100)}-{rpm}" + ("" if limit else "-nolimit"),
                        group="regen" if limit else "regen-nolimit",
                        label=f"{int(frac * 100)} % rated overhauling load ramped in over 4 s at {rpm} rpm"
                        + ("" if limit else ", regeneration limit off"),
                        duration=8.0,
                        speed=[(T_REF, float(rpm))],
                        load=load_ramp(2.0, 4.0, -frac * RATED_TORQUE),
                        sets=[] if limit else ["drive.loops.regen_min_frequency_hz=0"],
                        target=float(rpm),
                        tol=HOLD_TOL,
                    )
                )
    return out


def cases_reversal():
    return [
        Case(
            name="reversal-750",
            group="reversal",
            label="reversal +750 -> -750 rpm against a 50 % rated active load",
            duration=8.5,
            speed=[(T_REF, 750.0), (4.0, -750.0)],
            load=[(3.0, 0.5 * RATED_TORQUE)],
            kind="reversal",
            event=4.0,
            target=-750.0,
        )
    ]


def cases_ramp():
    return [
        Case(
            name="ramp-1500",
            group="ramp",
            label="ramp 0 -> 1500 rpm, no load",
            duration=5.5,
            speed=[(T_REF, RATED_RPM)],
            kind="ramp",
            event=T_REF,
            target=RATED_RPM,
            ramp_end=T_REF + RATED_RPM / RAMP_RPM_S,
        )
    ]


PARAM_ERRORS = [
    ("L_M -15 %", {"lm": 0.85}),
    ("L_M +15 %", {"lm": 1.15}),
    ("R_R +30 %", {"rr": 1.3}),
    ("R_R -30 %", {"rr": 0.7}),
    ("Rs +20 %", {"rs": 1.2}),
    ("Rs -20 %", {"rs": 0.8}),
]


def cases_param_errors():
    """Each error at 75 and 750 rpm, rated motoring and regenerating load; ours also with its
    Rs estimation off, as motulator 0.5.0 has none (motulator's run is the same)."""
    out = []
    for label, err in PARAM_ERRORS:
        tag = label.replace(" ", "").replace("%", "").replace("+", "p").replace("-", "m").replace("_", "").lower()
        for rpm in (75, 750):
            for sign, what in ((1.0, "motoring"), (-1.0, "regenerating")):
                for rs_est in (True, False):
                    out.append(
                        Case(
                            name=f"err-{tag}-{rpm}-{what[:3]}" + ("" if rs_est else "-rsoff"),
                            group="errors" if rs_est else "errors-rsoff",
                            label=f"{label}|{rpm}|{what}",
                            duration=6.0,
                            speed=[(T_REF, float(rpm))],
                            load=load_ramp(3.0, 1.0, sign * RATED_TORQUE),
                            errors=err,
                            sets=[] if rs_est else ["drive.estimation.rs_estimation=false"],
                            target=float(rpm),
                            tol=HOLD_TOL,
                        )
                    )
    return out


def all_cases():
    return cases_steps() + cases_motoring_ramps() + cases_regen() + cases_reversal() + cases_ramp() + cases_param_errors()


# ---------------------------------------------------------------------------------------
# the metrics: one function for both drives


def analyse(case, s):
    """Metrics of one run from its time series (both drives alike)."""
    # what a drive does after it stopped (a fault switches it off: the rotor coasts or the
    # active load drives it) is not control: the series ends at the stop
    n = len(s.t)
    if s.stop_t is not None:
        n = sum(1 for x in s.t if x <= s.stop_t)
    t, w, we = s.t[:n], s.w[:n], s.w_est[:n]
    m = {"running": s.running, "stop": s.stop, "stop_t": s.stop_t}
    ref = [case.ref_rpm(x) for x in t]
    after = [i for i in range(n) if t[i] >= case.event]
    before = [i for i in range(n) if case.event - 0.2 <= t[i] < case.event]
    m["before"] = sum(w[i] for i in before) / len(before) if before else None
    m["limited_before"] = bool(s.limited) and any(s.limited[i] for i in before)
    if case.kind == "step":
        band = 0.01 * abs(case.target)
        err = [case.target - w[i] for i in after]
        m["dip"] = max(abs(e) for e in err) if err else None
        outside = [t[i] for i in after if abs(case.target - w[i]) > band]
        if not outside:
            m["back"] = 0.0
        elif outside[-1] >= t[-1] - 1e-9 or not s.running:
            m["back"] = None  # not back by the end
        else:
            m["back"] = outside[-1] - case.event
        m["est_err"] = max(abs(we[i] - w[i]) for i in after) if after else None
    elif case.kind == "reversal":
        m["track_max"] = max(abs(ref[i] - w[i]) for i in after) if after else None
        m["est_err"] = max(abs(we[i] - w[i]) for i in after) if after else None
    elif case.kind == "ramp":
        idx = [i for i in range(n) if case.event <= t[i] <= case.ramp_end]
        m["rms"] = math.sqrt(sum((ref[i] - w[i]) ** 2 for i in idx) / len(idx)) if idx else None
        m["track_max"] = max(abs(ref[i] - w[i]) for i in idx) if idx else None
    last = [i for i in range(n) if t[i] >= case.duration - 1.0]
    m["limited"] = bool(s.limited) and any(s.limited[i] for i in last)
    if s.running and last:
        ws = [w[i] for i in last]
        m["mean"] = sum(ws) / len(ws)
        m["pp"] = max(ws) - min(ws)
        m["dev"] = max(abs(x - case.target) for x in ws)
    else:
        m["mean"] = m["pp"] = m["dev"] = None
    m["held"] = bool(s.running and m["dev"] is not None and m["dev"] <= case.tol)
    if case.kind == "step":
        # back in control: within 1 % of the reference by the end
        m["held"] = bool(s.running and m["back"] is not None)
    return m


def check_reference(case, s):
    """Our drive's own reference against the benchmark's (the same ramp from the same
    instants), where the drive does not limit its target: the premise of the comparison."""
    if s.drive_ref is None or any(s.limited) or not s.running:
        return None
    # one control period of lag and rounding: RAMP_RPM_S x 2 periods is 0.2 rpm
    worst = max(abs(r - case.ref_rpm(x)) for x, r in zip(s.t, s.drive_ref))
    return worst


# ---------------------------------------------------------------------------------------
# the page


def fmt(v, d=1):
    if v is None:
        return "-"
    if abs(v) >= 1000:
        return f"{v:.0f}"
    return f"{v:.{d}f}"


def stopped(m):
    """How a run that is no longer in control ended."""
    at = f" at {m['stop_t']:.2f} s" if m["stop_t"] is not None else ""
    return f"**{m['stop']}**{at}"


def cell_hold(m, target=None):
    """Held or not, with the last second's mean and peak-to-peak speed (or the mean error)."""
    if not m["running"]:
        return stopped(m)
    word = "held" if m["held"] else "**not held**"
    lim = " (target limited)" if m["limited"] else ""
    if target is None:
        return f"{word}: {fmt(m['mean'])} / {fmt(m['pp'])}{lim}"
    return f"{word}, {m['mean'] - target:+.1f}{lim}"


def held_targets(results, frac, suffix, side):
    held = [rpm for rpm in REGEN_SPEEDS if results[f"regen-{int(frac * 100)}-{rpm}{suffix}"][side]["held"]]
    if not held:
        return "none"
    return f"{min(held)} rpm (held: {', '.join(str(r) for r in held)})"


def count(results, names, side):
    ms = [results[n][side] for n in names if n in results]
    held = sum(1 for m in ms if m["held"])
    faults = sum(1 for m in ms if not m["running"])
    text = f"{held} of {len(ms)} held"
    if faults:
        text += f", {faults} stopped ({', '.join(sorted(set(m['stop'].split(' at ')[0] for m in ms if not m['running'])))})"
    return text


def write_page(results, times, versions, ref_checks):
    L = []
    add = L.append
    add("<!-- generated by benches/peer/run.sh (benches/peer/peer.py): do not edit, rerun it -->")
    add("")
    add("# This drive against motulator 0.5.0")
    add("")
    add(
        "A side-by-side benchmark on motulator's own 2.2 kW induction machine "
        "([crates/acim-sim/machines/motulator-2k2.toml](../crates/acim-sim/machines/motulator-2k2.toml): "
        "R_s 3.7, R_R 2.1 ohm, L_sigma 0.021, L_M 0.224 H in inverse-Gamma form, 2 pole pairs, "
        "J 0.015 kg m^2; 400 V, 5 A, 50 Hz, 14.6 N m nominal) on a 540 V bus. "
        "[motulator](https://github.com/Aalto-Electric-Drives/motulator) is Aalto University's open drive simulator; "
        "its sensorless induction-motor control (`motulator.drive.control.im.CurrentVectorControl`) is a "
        "reduced-order flux observer with speed adaptation in estimated rotor-flux coordinates, a 2-DOF PI "
        "speed controller and a complex-vector PI current controller, set up here as in its 2.2 kW example "
        "with its default tuning. Each drive runs sensorless and closed loop in its own simulator."
    )
    add("")
    add(
        "Scope: ideal plants only, as the comparison is meant: no sensor noise or offsets, no dead time, "
        "no switching ripple, no drift of the machine's parameters. Those are what our drive's "
        "identification, tracking and supervision are for, and an ideal plant does not exercise them; "
        "the parameter-error cases below are the one place where the controller's model is wrong."
    )
    add("")
    add("What is the same in every case:")
    add("")
    add(
        "- the plant: the same machine with ideal electrics in both simulators: no dead time, no device "
        "drop, ideal current measurement (ours: 16-bit, 20 A full scale, no noise, gain or offset error), "
        "averaged PWM, a stiff 540 V bus, and no friction (motulator's plant has none; the machine file's "
        "2e-3 N m s/rad is set to 0);"
    )
    add(
        f"- the current limit: {CURRENT_LIMIT:.2f} A peak = 1.5 x the rated 7.07 A peak "
        "(motulator's `max_i_s`; ours from the nameplate);"
    )
    add(
        "- the flux: both derive it from the rated voltage and frequency (motulator: "
        "i_sd = psi_R,nom / L_M = 4.243 A; ours: the no-load current at rated voltage, 4.238 A);"
    )
    add(
        f"- the speed reference: a ramp at {RAMP_RPM_S:.0f} rpm/s (this drive's ramp from the nameplate) "
        f"from the same instants, given to motulator as its reference function; every reference step "
        f"is at t >= {T_REF} s, after our drive's start sequence (offset measurement, magnetizing, "
        "inverter test: about 1 s); motulator magnetizes from t = 0;"
    )
    add(
        f"- the load: an active (constant) torque, positive opposing forward rotation; rated = "
        f"{RATED_TORQUE} N m (motulator's nominal torque); a load ramp is 10 equal steps;"
    )
    add(
        "- the metrics: one Python function (`analyse` in `benches/peer/peer.py`) computes every number "
        "below from each drive's time series (true speed, estimated speed, and whether the drive still "
        "runs) against the common reference. A run ends, for the metrics and the figures, where the drive "
        "switched itself off (our faults); motulator has no such stop."
    )
    add("")
    add("## Reproduce")
    add("")
    add("```sh")
    add("cargo build --release -p acim-sim     # our side (or point ACIM_SIM at a built acim-sim)")
    add("bash benches/peer/run.sh              # both sides: this page and docs/figures/peer/")
    add("bash benches/peer/run.sh --ours-only  # our side only: no venv, nothing written under docs/")
    add("```")
    add("")
    add(
        "`run.sh` makes a venv in `benches/peer/.venv` with Python 3.11 (motulator 0.5.0 is its last "
        "release for Python 3.11) and the pinned packages of `benches/peer/requirements.txt`, then runs "
        "`benches/peer/peer.py`, where each case is one function giving our scenario TOML and the "
        "matching motulator setup."
    )
    add("")
    add(
        f"Run times on the machine that wrote this page ({os.cpu_count()} cores): this drive "
        f"{times['n']} runs, {times['sim_s']:.0f} s simulated in {times['ours_sim']:.1f} s of wall-clock time "
        f"summed over the runs (the CLI, CSV and plots included; our runs go {os.cpu_count()} at a time, so "
        f"each shares the machine); motulator {times['n_motulator']} runs, one at a time (a case that differs "
        f"only in our settings reuses its run), {times['motulator_sim_s']:.0f} s simulated in "
        f"{times['motulator']:.0f} s. Versions: {versions}."
    )
    add("")

    # -- overview
    steps = [c.name for c in cases_steps() if not c.sets]
    motoring = [c.name for c in cases_motoring_ramps()]
    regen = [c.name for c in cases_regen() if c.group == "regen"]
    regen_off = [c.name for c in cases_regen() if c.group == "regen-nolimit"]
    errs = [c.name for c in cases_param_errors() if c.group == "errors"]
    errs_off = [c.name for c in cases_param_errors() if c.group == "errors-rsoff"]
    add("## Overview")
    add("")
    add("| cases | motulator | this drive (the flux observer, the default from the nameplate) | this drive, the paper's observer |")
    add("|---|---|---|---|")
    add(f"| rated-load steps at 750, 75, 30 rpm (back in control: within 1 % of the reference at the end) | {count(results, steps, 0)} | {count(results, steps, 1)} | {count(results, steps, 2)} |")
    add(f"| rated motoring load ramped in at 45, 30, 15, 0 rpm (within +/-{HOLD_TOL_MOTORING:.0f} rpm) | {count(results, motoring, 0)} | {count(results, motoring, 1)} | {count(results, motoring, 2)} |")
    add(f"| overhauling 25/50/100 % load at 15-75 rpm (within +/-{HOLD_TOL:.0f} rpm) | {count(results, regen, 0)} | {count(results, regen, 1)} (no regeneration limit) | regeneration limit on: {count(results, regen, 2)}; off: {count(results, regen_off, 2)} |")
    add(f"| controller parameter errors (within +/-{HOLD_TOL:.0f} rpm) | {count(results, errs, 0)} | {count(results, errs, 1)}; Rs estimation off: {count(results, errs_off, 1)} | {count(results, errs, 2)}; Rs estimation off: {count(results, errs_off, 2)} |")
    add("")
    add(
        "The step rows count a run as held when it is back within 1 % of the reference by the end. "
        "Details, definitions and every number follow; the paper's observer's runs are in the section "
        "[with the paper's observer](#this-drive-with-the-papers-observer)."
    )
    add("")

    # -- steps
    add("## Rated-load steps")
    add("")
    add(
        "A 14.6 N m active load stepped in once the speed has settled. Peak dip: the largest "
        "|reference - speed| after the step; back within 1 %: time from the step to the last sample "
        "outside 1 % of the reference (\"not back\": still outside at the end or switched off); "
        "estimation error: the largest |estimated - true speed| after the step. At 75 and 30 rpm the "
        "dip is larger than the speed: the load drives the rotor backwards before the speed loop answers, "
        "and the drive must recover through zero speed. The paper's observer is also run there with its "
        "regeneration limit off (its section below; the default drive has no such limit)."
    )
    add("")
    add(
        "| target | before the step (rpm): motulator | this drive | peak dip (rpm): motulator | this drive "
        "| back within 1 % (s): motulator | this drive | est. error (rpm): motulator | this drive |"
    )
    add("|---|---|---|---|---|---|---|---|---|")
    for c in cases_steps():
        # the limit-off runs differ only with the paper's observer (its section below)
        if c.name not in results or c.sets:
            continue
        mo, ou = results[c.name][:2]

        def back(m):
            if not m["running"]:
                return stopped(m)
            return "not back" if m["back"] is None else fmt(m["back"], 3)

        lim = " (target limited)" if ou["limited_before"] else ""
        add(
            f"| {c.label} (step at {c.event} s) | {fmt(mo['before'])} | {fmt(ou['before'])}{lim} | {fmt(mo['dip'])} | {fmt(ou['dip'])} "
            f"| {back(mo)} | {back(ou)} | {fmt(mo['est_err'])} | {fmt(ou['est_err'])} |"
        )
    add("")
    if any(results[c.name][1]["limited_before"] for c in cases_steps() if c.name in results):
        add(
            "\"Target limited\" before a step: the regeneration limit allows no braking current below "
            "1.5 Hz stator frequency (45 rpm at no load); with no friction in the plant, a small residual "
            "torque carried the rotor above the target to where braking is allowed, and the drive held "
            "that speed and reported its target limited. With the limit off it runs at the target."
        )
        add("")

    # -- motoring ramps
    add("## Rated motoring load ramped in at low speed")
    add("")
    add(
        "14.6 N m ramped in over 1 s (from 2.0 s); mean / peak-to-peak true speed over the last second "
        f"(4-5 s). Held: in control and the speed within +/-{HOLD_TOL_MOTORING:.0f} rpm of the target over "
        "the last second. At 0 rpm our drive holds the zero target with the flux on "
        "(`--set drive.zero_speed.policy=hold`; its default switches off at a held zero target)."
    )
    add("")
    add("| target (rpm) | motulator: mean / p-p (rpm) | this drive: mean / p-p (rpm) |")
    add("|---|---|---|")
    for c in cases_motoring_ramps():
        if c.name in results:
            mo, ou = results[c.name][:2]
            add(f"| {c.target:.0f} | {cell_hold(mo)} | {cell_hold(ou)} |")
    add("")

    # -- regeneration
    add("## Overhauling (regenerating) load at low speed")
    add("")
    add(
        "An active load driving the rotor forwards, ramped in over 4 s (from 2.0 s), at a target of "
        f"{', '.join(str(r) for r in REGEN_SPEEDS)} rpm. Held: in control and the true speed within "
        f"+/-{HOLD_TOL:.0f} rpm of the target over the last second (7-8 s). Our default drive (the flux "
        "observer) has no regeneration limit, nor has motulator. With the paper's observer the drive keeps "
        "one (on by default, `drive.loops.regen_min_frequency_hz` = 1.5): braking operating points stay 1.5 Hz "
        "away from zero stator frequency, the drive holds the speed it can reach there and reports the target "
        "limited (\"target limited\" below: the drive ran above its target, inside the 30 rpm band or not); "
        "off: `--set drive.loops.regen_min_frequency_hz=0`."
    )
    add("")
    have = all(f"regen-{int(f * 100)}-{r}{x}" in results for f in REGEN_FRACTIONS for r in REGEN_SPEEDS for x in ("", "-nolimit"))
    if have:
        add("| load | motulator: lowest target held | this drive | paper's observer, limit on | paper's observer, limit off |")
        add("|---|---|---|---|---|")
        for frac in REGEN_FRACTIONS:
            add(
                f"| {int(frac * 100)} % ({frac * RATED_TORQUE:.2f} N m) | {held_targets(results, frac, '', 0)} "
                f"| {held_targets(results, frac, '', 1)} | {held_targets(results, frac, '', 2)} "
                f"| {held_targets(results, frac, '-nolimit', 2)} |"
            )
        add("")
        add("Each run: held or not, and the mean / peak-to-peak true speed over the last second (rpm), or how it ended:")
        add("")
        add("| load | target (rpm) | motulator | this drive | paper's observer, limit on | paper's observer, limit off |")
        add("|---|---|---|---|---|---|")
        for frac in REGEN_FRACTIONS:
            for rpm in REGEN_SPEEDS:
                a = results[f"regen-{int(frac * 100)}-{rpm}"]
                b = results[f"regen-{int(frac * 100)}-{rpm}-nolimit"]
                add(f"| {int(frac * 100)} % | {rpm} | {cell_hold(a[0])} | {cell_hold(a[1])} | {cell_hold(a[2])} | {cell_hold(b[2])} |")
        add("")

    # -- reversal and ramp
    add("## Reversal and ramp tracking")
    add("")
    add("| case | motulator | this drive |")
    add("|---|---|---|")
    for c in cases_reversal():
        if c.name in results:
            mo, ou = results[c.name][:2]
            f = lambda m: (f"max tracking error {fmt(m['track_max'])} rpm; max est. error {fmt(m['est_err'])} rpm" if m["running"] else stopped(m))
            add(f"| {c.label}: load from 3.0 s, reversal from {c.event} s, errors from then to the end | {f(mo)} | {f(ou)} |")
    for c in cases_ramp():
        if c.name in results:
            mo, ou = results[c.name][:2]
            f = lambda m: (f"rms error {fmt(m['rms'], 2)} rpm; max {fmt(m['track_max'], 2)} rpm" if m["running"] else stopped(m))
            add(f"| {c.label}, {RAMP_RPM_S:.0f} rpm/s ({c.event}-{c.ramp_end} s; reference - speed during the ramp) | {f(mo)} | {f(ou)} |")
    add("")

    # -- parameter errors
    add("## Parameter errors in the controller")
    add("")
    add(
        "One parameter of the controller's machine model off, the plant unchanged; rated load ramped in "
        "over 1 s from 3.0 s, motoring (+14.6 N m) or regenerating (-14.6 N m), at 75 or 750 rpm. Our "
        "`[controller]` is the inverse-Gamma model as a T-model (lr_h = lm_h = L_M, ls_h = L_sigma + L_M, "
        "rr_ohm = R_R); motulator's controller parameters are scaled the same way. Both derive the flux "
        f"from the (wrong) parameters. Held: in control and the true speed within +/-{HOLD_TOL:.0f} rpm "
        "of the target over the last second; the number is the mean speed error over that second "
        "(true - target, rpm). Our drive identifies Rs at standstill and adapts it while running (its "
        "default); motulator 0.5.0 has no Rs adaptation, so ours is also run with its Rs estimation off "
        "(`--set drive.estimation.rs_estimation=false`; motulator's run is the same)."
    )
    add("")
    add("| error | speed (rpm) | load | motulator | this drive | this drive, Rs estimation off |")
    add("|---|---|---|---|---|---|")
    for c in cases_param_errors():
        if c.group == "errors" and c.name in results and c.name + "-rsoff" in results:
            mo, ou = results[c.name][:2]
            off = results[c.name + "-rsoff"][1]
            label, rpm, what = c.label.split("|")
            add(f"| {label} | {rpm} | {what} | {cell_hold(mo, c.target)} | {cell_hold(ou, c.target)} | {cell_hold(off, c.target)} |")
    add("")

    # -- figures
    add("## Figures")
    add("")
    add("Solid: true speed; dotted: the drive's speed estimate; dashed: the common reference; dash-dotted: a drive switching itself off.")
    add("")
    for name, (title, _) in FIGURE_CASES.items():
        if (FIGURES / f"{name}.png").exists():
            add(f"![{title}](figures/peer/{name}.png)")
            add("")
    # -- the paper's observer
    add("## This drive with the paper's observer")
    add("")
    add(
        "Every case again with the paper's reduced-order observer of speed and load torque, "
        "`--set drive.observer=reduced` (`acim::observer`, the drive's default before the flux observer; "
        "the paper's figures are reproduced with it), with the orientation correction, the far-side mode "
        "and the regeneration limit it needs near zero stator frequency while regenerating, and the running "
        "Rs law adapting at every speed. The default drive runs the flux observer (`acim::flux_observer`): "
        "motulator's structure and gain, giving the speed to our indirect field orientation, no "
        "regeneration limit and no orientation correction, the running Rs law only at low stator "
        "frequency (below Rs/L_M) and with a torque current of at least 1.5 w_s lambda / Rs, where an "
        "inductance error of 15 % cannot pull it by more than 5 % (`acim::rs_estimator`). "
        "Cells: steps, peak dip / back within 1 % (s); holds, held or not with the last second's mean / "
        "peak-to-peak speed (rpm); the reversal and the ramp, the largest tracking error (rpm)."
    )
    add("")
    add("| case | motulator | this drive | this drive, paper's observer |")
    add("|---|---|---|---|")

    def cell_any(m):
        if m is None:
            return ""
        if m.get("dip") is not None:
            if not m["running"]:
                return stopped(m)
            back = "not back" if m["back"] is None else fmt(m["back"], 3)
            return f"{fmt(m['dip'])} / {back}"
        if m.get("track_max") is not None:
            return stopped(m) if not m["running"] else f"{fmt(m['track_max'])}"
        return cell_hold(m)

    for c in all_cases():
        if c.name not in results or c.name.endswith("-nolimit"):
            continue
        mo, ou, pa = results[c.name]
        add(f"| {c.name} | {cell_any(mo)} | {cell_any(ou)} | {cell_any(pa)} |")
    add("")

    add("## Where the two are not alike")
    add("")
    L += NOT_ALIKE
    add("")
    if ref_checks:
        add(
            f"Check: in the {len(ref_checks)} runs where our drive did not limit its target, its own ramped "
            f"reference stayed within {max(ref_checks.values()):.2f} rpm of the common reference that "
            "motulator was given."
        )
        add("")
    PAGE.write_text("\n".join(L))


NOT_ALIKE = [
    "- **Sampling.** motulator samples and updates the PWM every 250 us (4 kHz, its default); this drive "
    "every 200 us (5 kHz, its default from the board). Both model one sample of computational delay and "
    "advance the voltage angle by 1.5 samples.",
    "- **PWM and plant model.** Both average the PWM over a period (motulator: zero-order hold of the "
    "duty ratios; ours: the period's average voltage); neither switches. motulator integrates its plant "
    "(Gamma model) with scipy's adaptive `solve_ivp`, ours (T model, the same machine) with fixed-step "
    "RK4, 5 substeps a period.",
    "- **Observer and orientation.** motulator: a reduced-order flux observer in estimated rotor-flux "
    "coordinates with speed adaptation, gain k_o = (0.5 alpha + 0.2 |w_m|)/(alpha - j w_m) with "
    "alpha = R_R/L_M, speed-adaptation bandwidth 2 pi 40 rad/s; its gain leans on the voltage model as "
    "the speed rises; motulator orients on its observer's flux. Ours: indirect field orientation (the slip "
    "from the current model with R_R and L_M) with the speed of a flux observer of motulator's structure "
    "and gain (`acim::flux_observer`), with a load-torque observer added, the voltage taken over the period "
    "it acted in, the adapted speed bounded by what the rotor can do, and the frame locked onto the "
    "observer's flux angle at higher stator frequency. The paper's reduced-order observer of speed and load "
    "torque (its own section above) adds an orientation correction from the d-axis residual and, past its "
    "regeneration limit, a far-side mode.",
    "- **Rs adaptation.** motulator 0.5.0 has none; ours identifies Rs at standstill at each start and "
    "adapts it while running (default). Our start also identifies the inverter's voltage error (here "
    "zero) and calibrates the current sensors' gains; motulator starts at once.",
    "- **Speed control.** motulator: 2-DOF PI, alpha_s = 2 pi 4 = 25.1 rad/s (k_p = 2 alpha_s J, "
    "k_i = alpha_s^2 J, reference gain k_t = alpha_s J), no acceleration feed-forward, so it lags a ramp. "
    "Ours (from the nameplate): proportional feedback kp = 2 alpha J / k_t with alpha = 31 rad/s (a rated "
    "step may slow the rotor by at most 10 % of rated speed on the feedback alone), the observer's "
    "load-torque estimate as the integral action, the ramp's acceleration fed forward (`acim::speed_loop`).",
    "- **Current control and limit.** motulator: 2-DOF complex-vector PI, alpha_c = 2 pi 200 = 1257 rad/s; "
    "the q current is limited to the circle left by the d current and to a breakdown-torque limit, and "
    "the limited torque is its speed controller's anti-windup. Ours: PI current loops at 1000 rad/s, the "
    "q current limited to the circle left by the d current. The limit is the same, 10.61 A.",
    "- **Ratings.** Our drive rates the machine from its nameplate (2.2 kW at the synchronous 1500 rpm: "
    "14.0 N m); motulator's nominal torque, used here as rated load, is 14.6 N m. The load is the same "
    "for both.",
    "- **Field weakening.** motulator weakens the field from the unlimited voltage reference "
    "(95 % of the linear limit); ours from the steady-state voltage equations with a voltage-feedback "
    "trim at 92 % of the linear limit. Only the ramp to 1500 rpm reaches it.",
    "- **Supervision.** Ours supervises: faults (`Overload`, `LossOfControl`, `EstimatorOutOfRange`, ...) "
    "switch it off, and the regeneration limit holds a reachable speed and reports it. motulator has no "
    "supervision: a run that loses control keeps running, or "
    "stops if the solver meets a non-finite value. \"Held\" is judged from the true speed for both.",
    "- **Start.** motulator magnetizes from t = 0 with no delay; ours runs its start sequence (about 1 s). "
    "Every reference step is after both are magnetized, so each case starts from the same state.",
]


# ---------------------------------------------------------------------------------------
# figures


def figure(case, series, path, title, zoom_s):
    """Speed and its estimate against time, both drives: the whole run from just before the
    first reference step, and a zoom on the event. A drive that stopped is drawn to its stop."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    mo, ou, pa = series
    fig, ax = plt.subplots(2, 1, figsize=(8, 6.5))
    t0 = max(0.0, min(s for s, _ in case.speed) - 0.2)
    spans = ((t0, case.duration), (case.event - 0.2, min(case.duration, case.event + zoom_s)))
    for a, (lo, hi) in zip(ax, spans):
        tr = [x for x in ou.t if lo <= x <= hi]
        a.plot(tr, [case.ref_rpm(x) for x in tr], "k--", lw=1, label="reference")
        for s, lab, col in ((mo, "motulator 0.5.0", "tab:orange"), (ou, "this drive", "tab:blue"), (pa, "this drive, paper's observer", "tab:green")):
            end = s.stop_t if s.stop_t is not None else math.inf
            idx = [i for i, x in enumerate(s.t) if lo <= x <= hi and x <= end]
            a.plot([s.t[i] for i in idx], [s.w[i] for i in idx], color=col, lw=1.4, label=f"{lab}: speed")
            a.plot([s.t[i] for i in idx], [s.w_est[i] for i in idx], color=col, lw=0.9, ls=":", label=f"{lab}: estimate")
            if s.stop_t is not None and lo <= s.stop_t <= hi:
                a.axvline(s.stop_t, color=col, lw=0.8, ls="-.", label=f"{lab}: {s.stop} (switched off)")
        a.set_xlim(lo, hi)
        a.set_ylabel("speed (rpm)")
        a.grid(alpha=0.3)
    ax[0].set_title(title, fontsize=10)
    ax[0].legend(fontsize=7, loc="best")
    ax[1].set_xlabel("t (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


FIGURE_CASES = {
    "step-750": ("Rated-load step (14.6 N m at 3.5 s) at 750 rpm", 1.0),
    "step-75": ("Rated-load step (14.6 N m at 2.5 s) at 75 rpm", 1.0),
    "reversal-750": ("Reversal +750 -> -750 rpm (from 4 s) against a 7.3 N m active load (from 3 s)", 4.0),
}


# ---------------------------------------------------------------------------------------


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ours-only", action="store_true", help="run our side only (no motulator, nothing written under docs/)")
    ap.add_argument("--only", default="", help="cases whose name contains this (no page written)")
    ap.add_argument("--reuse", action="store_true", help="reuse motulator results cached in benches/peer/out (development)")
    args = ap.parse_args()

    sim = os.environ.get("ACIM_SIM", "target/release/acim-sim")
    if not os.path.isabs(sim):
        sim = str(ROOT / sim)
    if not os.access(sim, os.X_OK):
        sys.exit(f"peer.py: no simulator at {sim} (cargo build --release -p acim-sim, or set ACIM_SIM)")

    cases = [c for c in all_cases() if args.only in c.name]
    results, series, ref_checks = {}, {}, {}
    # wall-clock time of the simulations alone: our CLI process (simulation, CSV, JSON and
    # PNG written), motulator's Simulation.simulate
    times = {"ours": 0.0, "ours_sim": 0.0, "motulator": 0.0, "n": 0, "n_motulator": 0, "sim_s": 0.0, "motulator_sim_s": 0.0}
    problems = []
    SCRATCH.mkdir(exist_ok=True)
    cache_path = SCRATCH / "motulator-cache.json"
    # motulator's run of a case that differs from another only in our settings is the same
    # run: kept in memory, and in out/ for a later call with --reuse
    cache = json.loads(cache_path.read_text()) if (args.reuse and cache_path.exists()) else {}
    counted = set()
    with tempfile.TemporaryDirectory(prefix="acim-peer-") as tmp:
        # our runs (each case with the default observer and with the paper's) are
        # independent processes: they run as many at once as the machine has cores, each in
        # its own directory, and are read back in the cases' order
        def ours_timed(c, kind, extra):
            d = Path(tmp) / kind
            d.mkdir(exist_ok=True)
            t0 = time.perf_counter()
            series, wall = c.run_ours(sim, d, extra)
            return series, wall, time.perf_counter() - t0

        pool = concurrent.futures.ThreadPoolExecutor(max_workers=os.cpu_count() or 1)
        runs = [(pool.submit(ours_timed, c, "ours", ()), pool.submit(ours_timed, c, "paper", PAPER_SETS))
                for c in cases]
        for c, (ours_run, paper_run) in zip(cases, runs):
            try:
                ours, wall, total = ours_run.result()
            except RuntimeError as e:
                problems.append(str(e))
                print(f"{c.name}: our run failed", file=sys.stderr)
                continue
            times["ours"] += total
            times["ours_sim"] += wall
            times["sim_s"] += c.duration
            times["n"] += 1
            mo_m = None
            mo = None
            if not args.ours_only:
                key = json.dumps([c.speed, c.load, c.errors, c.duration])
                if key not in cache:
                    mo = c.run_motulator()
                    cache[key] = {"series": dict(mo.__dict__), "wall": c.wall}
                    cache_path.write_text(json.dumps(cache))
                mo = Series(**cache[key]["series"])
                if key not in counted:
                    # each distinct motulator run once (also when reused from an earlier call)
                    counted.add(key)
                    times["motulator"] += cache[key]["wall"]
                    times["motulator_sim_s"] += c.duration
                    times["n_motulator"] += 1
                mo_m = analyse(c, mo)
            ou_m = analyse(c, ours)
            # the same case with the paper's observer (`drive.observer = "reduced"`, with its
            # regeneration limit)
            try:
                paper = paper_run.result()[0]
            except RuntimeError as e:
                problems.append(str(e))
                print(f"{c.name}: our run with the paper's observer failed", file=sys.stderr)
                continue
            pa_m = analyse(c, paper)
            chk = check_reference(c, ours)
            if chk is not None:
                ref_checks[c.name] = chk
                if chk > 1.0:
                    problems.append(f"{c.name}: our drive's reference is {chk:.2f} rpm off the benchmark's ramp")
            results[c.name] = (mo_m, ou_m, pa_m)
            if c.name in FIGURE_CASES:
                series[c.name] = (mo, ours, paper)
            print(f"{c.name:28} ours: {summary(ou_m)}   paper's observer: {summary(pa_m)}" + ("" if mo_m is None else f"   motulator: {summary(mo_m)}"), flush=True)
        pool.shutdown(wait=True, cancel_futures=True)
    print(
        f"our side: {times['n']} runs, {times['sim_s']:.0f} s simulated in {times['ours_sim']:.1f} s "
        f"({times['ours']:.1f} s with reading the CSVs)"
        + ("" if args.ours_only else f"; motulator: {times['n_motulator']} runs, {times['motulator_sim_s']:.0f} s simulated in {times['motulator']:.0f} s")
    )
    (SCRATCH / ("results-ours.json" if args.ours_only else "results.json")).write_text(json.dumps(results, indent=1))
    if problems:
        print("\n".join(problems), file=sys.stderr)
        sys.exit(1)
    if args.ours_only or args.only:
        return
    import matplotlib
    import motulator  # noqa: F401  (the version for the page)
    import importlib.metadata as md

    versions = f"motulator {md.version('motulator')}, numpy {md.version('numpy')}, scipy {md.version('scipy')}, Python {sys.version.split()[0]}"
    FIGURES.mkdir(parents=True, exist_ok=True)
    byname = {c.name: c for c in cases}
    for name, (title, zoom) in FIGURE_CASES.items():
        figure(byname[name], series[name], FIGURES / f"{name}.png", title, zoom)
    write_page(results, times, versions, ref_checks)
    print(f"wrote {PAGE.relative_to(ROOT)} and {FIGURES.relative_to(ROOT)}/")


def summary(m):
    parts = []
    for k in ("dip", "back", "est_err", "track_max", "rms", "mean", "pp"):
        if k in m and m[k] is not None:
            parts.append(f"{k} {m[k]:.2f}")
    parts.append("held" if m["held"] else ("running" if m["running"] else m["stop"]))
    if m["limited"]:
        parts.append("limited")
    return ", ".join(parts)


if __name__ == "__main__":
    main()
