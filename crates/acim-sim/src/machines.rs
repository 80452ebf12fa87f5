//! The any-motor acceptance: the machines of `crates/acim-sim/machines/`, each
//! commissioned from its nameplate against its plant, then driven with the identified
//! model only through the acceptance scenarios. Shared by `acim-sim any-motor` (the
//! README table and `docs/any-motor/`) and `tests/any_motor.rs`.

use crate::commission::{Report, Run};
use crate::scenario::{
    machine_file_as_scenario, LoadKind, LoadPoint, MachineSpec, Scenario, SpeedPoint, Window,
};

/// One acceptance machine: its file's name and text.
#[derive(Clone, Copy, Debug)]
pub struct MachineFile {
    /// File stem, e.g. `motulator-2k2`.
    pub name: &'static str,
    /// The TOML text (`[nameplate]`, `[plant]`, `[inverse_gamma]`, `[board]`, ...).
    pub text: &'static str,
}

/// The acceptance machines.
pub const MACHINES: [MachineFile; 7] = [
    MachineFile {
        name: "paper-750w",
        text: include_str!("../machines/paper-750w.toml"),
    },
    MachineFile {
        name: "ti-aci-benchmark",
        text: include_str!("../machines/ti-aci-benchmark.toml"),
    },
    MachineFile {
        name: "motulator-2k2",
        text: include_str!("../machines/motulator-2k2.toml"),
    },
    MachineFile {
        name: "motulator-2k2-saturated",
        text: include_str!("../machines/motulator-2k2-saturated.toml"),
    },
    MachineFile {
        name: "krause-50hp",
        text: include_str!("../machines/krause-50hp.toml"),
    },
    MachineFile {
        name: "simscape-7k5",
        text: include_str!("../machines/simscape-7k5.toml"),
    },
    MachineFile {
        name: "emwb-180w",
        text: include_str!("../machines/emwb-180w.toml"),
    },
];

/// The machine as a scenario with realistic sensors: 0.1 % noise, the paper's gain and
/// offset errors. TI's file assumes a 750 W rating the machine cannot make at 3 A
/// (`acim::nameplate` refuses it): 600 W here.
pub fn base(m: &MachineFile) -> Result<Scenario, String> {
    let mut sc = Scenario::from_toml(&machine_file_as_scenario(m.text))
        .map_err(|e| format!("{}: {e}", m.name))?;
    sc.name = m.name.to_string();
    if m.name == "ti-aci-benchmark" {
        if let Some(n) = sc.nameplate.as_mut() {
            n.power_w = 600.0;
        }
    }
    let fs = sc.board.map_or(10.0, |b| b.current_full_scale_a);
    sc.sensors.noise_a = 1e-3 * fs;
    sc.sensors.gain_error = [0.003, -0.003, 0.0];
    sc.sensors.offset_a = [5e-4 * fs, -5e-4 * fs, 0.0];
    Ok(sc)
}

/// Rated speed (rpm) and torque (N m) of the machine's nameplate.
pub fn rated(sc: &Scenario) -> Result<(f32, f32), String> {
    let n = sc.nameplate.ok_or("no [nameplate]")?;
    let r = acim::nameplate::Nameplate {
        power_w: n.power_w,
        voltage_v: n.voltage_v,
        current_a: n.current_a,
        frequency_hz: n.frequency_hz,
        speed_rpm: n.speed_rpm,
        power_factor: n.power_factor,
        pole_pairs: n.pole_pairs,
    }
    .rated()
    .map_err(|e| e.to_string())?;
    Ok((r.speed * acim::math::RAD_S_TO_RPM, r.torque))
}

/// `base` with the controller's model and dead-time compensation from commissioning (the
/// T-model equivalent of the identified inverse-Gamma model); where commissioning does
/// not resolve the inertia, the plant's stands in (reported).
pub fn identified(base: &Scenario, report: &Report) -> Scenario {
    let mut s = base.clone();
    let (l_m, l_s, r_r) = (
        report.l_m_h.identified,
        report.l_sigma_h.identified,
        report.rr_ohm.identified,
    );
    let l = l_m + l_s;
    s.controller = MachineSpec {
        rs_ohm: report.rs_ohm.identified,
        rr_ohm: r_r * l / l_m,
        ls_h: l,
        lr_h: l,
        lm_h: (l_m * l).sqrt(),
        pole_pairs: base.plant.pole_pairs,
        inertia_kgm2: report
            .inertia_kgm2
            .map_or(base.plant.inertia_kgm2, |j| j.identified),
        friction_nms: report.friction_nms.identified,
    };
    s.drive.inverter.dead_time_comp_s = report.dead_time_s.identified;
    s
}

fn sp(t_s: f32, rpm: f32) -> SpeedPoint {
    SpeedPoint { t_s, rpm }
}

fn win(name: &str, from_s: f32, to_s: f32) -> Window {
    Window {
        name: name.into(),
        from_s,
        to_s,
    }
}

/// The acceptance scenarios on `sc` (rated speed `n` rpm, rated torque `t` N m):
/// start to 1/3 rated speed, a rated-load step, the load off and a reversal; a trapezoid
/// at 3 % of rated speed; 70 % rated regeneration at 1/3 rated speed.
pub fn scenarios(sc: &Scenario, n: f32, t: f32) -> [Scenario; 3] {
    let third = n / 3.0;
    let mut a = sc.clone();
    a.name = format!("{}-load-reversal", sc.name);
    a.description = "identified model: 1/3 rated speed, rated-load step, reversal".into();
    a.duration_s = 9.0;
    a.speed_profile = vec![sp(0.5, third), sp(5.0, -third)];
    a.load_profile = vec![
        LoadPoint {
            t_s: 3.0,
            kind: LoadKind::Passive,
            torque_nm: t,
        },
        LoadPoint {
            t_s: 5.0,
            kind: LoadKind::None,
            torque_nm: 0.0,
        },
    ];
    a.windows = vec![
        win("no-load", 2.5, 3.0),
        win("rated-load", 4.5, 5.0),
        win("reversed", 8.5, 9.0),
    ];
    let mut b = sc.clone();
    b.name = format!("{}-trapezoid-3pct", sc.name);
    b.description = "identified model: trapezoid at 3 % of rated speed".into();
    b.duration_s = 8.0;
    b.speed_profile = vec![sp(0.5, 0.03 * n), sp(4.0, -0.03 * n), sp(8.0, 0.0)];
    b.windows = vec![win("forward", 3.0, 4.0), win("reverse", 7.0, 8.0)];
    let mut c = sc.clone();
    c.name = format!("{}-regen-70", sc.name);
    c.description = "identified model: 70 % rated torque overhauling at 1/3 rated speed".into();
    c.duration_s = 8.0;
    c.speed_profile = vec![sp(0.5, third)];
    c.load_profile = vec![LoadPoint {
        t_s: 3.0,
        kind: LoadKind::Active,
        torque_nm: -0.7 * t,
    }];
    c.windows = vec![win("regenerating", 6.0, 8.0)];
    [a, b, c]
}

/// Commissions machine `m` and returns its run (the report, the trace the figures are
/// drawn from), its acceptance scenarios with the identified model and its rated speed
/// (rpm). A refused result is an error with the refusal.
pub fn prepare(m: &MachineFile) -> Result<(Run, [Scenario; 3], f32), String> {
    let sc = base(m)?;
    let run = crate::commission::run(&sc)?;
    if let Some(e) = &run.report.refusal {
        return Err(format!("{}: {e}", m.name));
    }
    let (n, t) = rated(&sc)?;
    let identified = identified(&sc, &run.report);
    Ok((run, scenarios(&identified, n, t), n))
}
