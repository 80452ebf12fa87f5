//! `acim-sim commission`: the drive's self-commissioning ([`acim::commissioning`]) run
//! against the plant of a scenario (its inverter and sensor imperfections included), and
//! the result as `identified.toml` with the true values and the errors.

use crate::scenario::Scenario;
use crate::sim::build_plant;
use acim::commissioning::{Commissioning, Identified, Stage};
use acim::nameplate::Nameplate;
use acim::DriveInputs;
use acim_plant::{LoadTorque, PwmPreload};
use serde::Serialize;

/// Longest commissioning, simulated s (the bound is 60 s).
pub const TIMEOUT_S: f32 = 60.0;

/// Identified against true values.
#[derive(Serialize, Clone, Copy, Debug, PartialEq)]
pub struct Pair {
    /// Identified.
    pub identified: f32,
    /// The plant's.
    pub true_value: f32,
    /// (identified - true) / true, %.
    pub error_pct: f32,
}

fn pair(identified: f32, true_value: f32) -> Pair {
    Pair {
        identified,
        true_value,
        error_pct: 100.0 * (identified - true_value) / true_value,
    }
}

/// What commissioning found.
#[derive(Serialize, Clone, Debug, PartialEq)]
pub struct Report {
    /// Scenario name.
    pub name: String,
    /// Rs, ohm.
    pub rs_ohm: Pair,
    /// R_R, ohm.
    pub rr_ohm: Pair,
    /// L_sigma, H.
    pub l_sigma_h: Pair,
    /// L_M at rated flux, H.
    pub l_m_h: Pair,
    /// Rated flux current (no-load current), A peak; the true value is the plant's
    /// no-load current at the same voltage and frequency.
    pub rated_flux_current_a: f32,
    /// J, kg m^2 (`None`: not resolved, see [`Identified::inertia`]).
    pub inertia_kgm2: Option<Pair>,
    /// B, N m s/rad (identified; the true viscous friction for comparison).
    pub friction_nms: Pair,
    /// Dead time, s.
    pub dead_time_s: Pair,
    /// Inverter voltage error per leg, V.
    pub inverter_error_v: f32,
    /// Device drop assumed (the board's), V.
    pub device_drop_v: f32,
    /// Electrical sequence time, simulated s.
    pub electrical_s: f32,
    /// Whole commissioning time, simulated s.
    pub total_s: f32,
}

impl Report {
    /// `identified.toml`: `[inverse_gamma]`, `[mechanics]`, `[inverter]` and, per
    /// quantity, the true value and the error in `[check]`.
    pub fn toml(&self) -> String {
        let p = |k: &str, x: &Pair| {
            format!(
                "{k} = {{ identified = {}, true = {}, error_pct = {:.3} }}\n",
                x.identified, x.true_value, x.error_pct
            )
        };
        let mut s = format!(
            "# written by `acim-sim commission` for `{}`\n\n[inverse_gamma]\nrs_ohm = {}\nrr_ohm = {}\nl_sigma_h = {}\nl_m_h = {}\nrated_flux_current_a = {}\n\n[mechanics]\ninertia_kgm2 = {}\nfriction_nms = {}\n\n[inverter]\ndead_time_s = {}\ndevice_drop_v = {}\n\n[check]\n",
            self.name,
            self.rs_ohm.identified,
            self.rr_ohm.identified,
            self.l_sigma_h.identified,
            self.l_m_h.identified,
            self.rated_flux_current_a,
            self.inertia_kgm2
                .map_or("nan # not resolved".to_string(), |j| j.identified.to_string()),
            self.friction_nms.identified,
            self.dead_time_s.identified,
            self.device_drop_v,
        );
        s += &p("rs_ohm", &self.rs_ohm);
        s += &p("rr_ohm", &self.rr_ohm);
        s += &p("l_sigma_h", &self.l_sigma_h);
        s += &p("l_m_h", &self.l_m_h);
        if let Some(j) = &self.inertia_kgm2 {
            s += &p("inertia_kgm2", j);
        }
        s += &p("friction_nms", &self.friction_nms);
        s += &p("dead_time_s", &self.dead_time_s);
        s += &format!(
            "commissioning_s = {:.2}\nelectrical_s = {:.2}\n",
            self.total_s, self.electrical_s
        );
        s
    }
}

/// Runs commissioning on `sc`'s plant, which needs `[nameplate]` and `[board]`.
pub fn commission(sc: &Scenario) -> Result<Report, String> {
    let v = sc.validate().map_err(|e| e.to_string())?;
    let (Some(np), Some(board)) = (sc.nameplate, v.board) else {
        return Err("commissioning needs [nameplate] and [board] (or --nameplate FILE)".into());
    };
    let nameplate = Nameplate {
        power_w: np.power_w,
        voltage_v: np.voltage_v,
        current_a: np.current_a,
        frequency_hz: np.frequency_hz,
        speed_rpm: np.speed_rpm,
        power_factor: np.power_factor,
        pole_pairs: np.pole_pairs,
    };
    nameplate.rated().map_err(|e| e.to_string())?;
    let mut plant = build_plant(sc, &v);
    let ts = 1.0 / board.pwm_frequency_hz;
    let mut pwm = PwmPreload::new();
    let mut com = Commissioning::new(&nameplate, &board).map_err(|e| e.to_string())?;
    let mut t = 0.0f32;
    // the plant's magnetizing inductance at the no-load test's flux (saturation)
    let mut at_rated_flux = v.plant;
    while !matches!(com.stage(), Stage::Done | Stage::Failed(_)) {
        if t > TIMEOUT_S {
            return Err(format!("commissioning: no result within {TIMEOUT_S} s"));
        }
        let m = plant.sample();
        let out = com.step(&DriveInputs {
            phase_currents: m.phase_currents,
            dc_bus: m.dc_bus,
        });
        if com.stage() == Stage::NoLoad {
            at_rated_flux = plant.machine().effective_params();
        }
        plant.set_dc_bus(sc.bus_v());
        plant.run_pwm_period(pwm.advance(out), LoadTorque::None);
        t += ts;
    }
    let electrical_s = t;
    if std::env::var_os("ACIM_COMMISSION_DEBUG").is_some() {
        eprintln!("{:?} {:?}", com.stage(), com.mechanics_sums());
    }
    let id: Identified = com
        .identify()
        .map_err(|e| format!("commissioning: {e:?}"))?;
    if std::env::var_os("ACIM_COMMISSION_DEBUG").is_some() {
        eprintln!("{id:#?}");
    }
    let p = v.plant;
    Ok(Report {
        name: sc.name.clone(),
        rs_ohm: pair(id.stator_resistance, p.stator_resistance()),
        rr_ohm: pair(id.rotor_resistance, p.referred_rotor_resistance()),
        l_sigma_h: pair(id.leakage_inductance, p.transient_inductance()),
        l_m_h: pair(
            id.magnetizing_inductance,
            at_rated_flux.magnetizing_inductance(),
        ),
        rated_flux_current_a: id.rated_flux_current,
        inertia_kgm2: id.inertia.map(|j| pair(j, p.inertia())),
        friction_nms: pair(id.viscous_friction, p.viscous_friction().max(1e-9)),
        dead_time_s: pair(id.dead_time, sc.inverter.dead_time_s),
        inverter_error_v: id.inverter_error,
        device_drop_v: board.device_drop_v,
        electrical_s,
        total_s: t,
    })
}
