//! Field weakening, over-voltage control and light-load flux optimisation: the flux
//! current i_sd* and the torque-current limits at this step's stator frequency, bus and
//! load ([`FieldWeakeningDesign`] for the equations).

use crate::config::DriveConfig;
use crate::frames::Dq;
use crate::math::sqrt;
use crate::num::DivSqrt;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;
use crate::svpwm::{VoltageLimit, FW_TRIM_FRACTION};

/// Field weakening keeps the steady-state stator voltage within this fraction of the
/// current loops' voltage limit: the margin the current loops keep for
/// transients and for what the model of [`FieldWeakeningDesign`] neglects. 0.97 keeps
/// the no-load voltage of the paper machine at rated flux and 1000 rpm (about 177 V of
/// the 184 V limit on 325 V) below it: the drive weakens the field only above that.
pub const FW_VOLTAGE_FRACTION: f32 = 0.97;

/// Field weakening lowers the flux current to no less than this fraction of
/// `flux_current` (the flux model's floor is 10 %, [`crate::flux`]).
pub const FW_MIN_FLUX_FRACTION: f32 = 0.15;

/// Light-load flux optimisation: the flux current never goes below this fraction of
/// `flux_current` (the observer's gains follow 1/lambda_r, and a load step must find
/// some flux to build torque on).
pub const FLUX_OPT_MIN_FRACTION: f32 = 0.5;

/// Light-load flux optimisation: the flux current falls towards a lower optimum with this
/// many rotor time constants (the flux follows it with one more); it rises at once.
pub const FLUX_OPT_FALL_TAU_R: f32 = 5.0;

/// Below this fraction of the base electrical frequency p Omega_base (linear limit at
/// `dc_bus_max`) the field-weakening model divides by this floor instead of |w_s|: there
/// its flux current is far above `flux_current` and the rated flux is kept.
pub const FW_MIN_FREQUENCY_FRACTION: f32 = 0.25;

/// Bandwidth of the field weakening's voltage-feedback trim, rad/s: the steady-state
/// loop gain of i_sd* -> |v| is w Ls, normalised by the 1/w of the trim; an order below
/// 1/tau_r of the paper machine (15 rad/s) so the lag of the flux does not destabilise it.
pub const FW_TRIM_BANDWIDTH: f32 = 30.0;

/// Field weakening (the model and the voltage-feedback trim) is evaluated only where the
/// no-load voltage at rated flux w Ls i_sd_rated exceeds this fraction of V (from about
/// 0.7 x base speed up): below it the rated flux is kept without computing anything, and
/// faults that saturate the current loops at lower speed do not move the flux. (A load
/// whose Rs i_sq drop alone exceeds 0.3 V below that speed is voltage-limited by the
/// current loops, as earlier.)
pub const FW_TRIM_GATE: f32 = 0.7;

/// Over-voltage control starts reducing the regenerative current at this fraction of
/// `dc_bus_max`.
pub const OVC_START_FRACTION: f32 = 0.9;

/// ... and allows none at this fraction.
pub const OVC_END_FRACTION: f32 = 0.975;

/// Field weakening and over-voltage control: a model-based flux reference
/// with a voltage-feedback trim.
///
/// Why this combination: a pure voltage-feedback loop (integrating |v*| - V into i_sd*)
/// needs the voltage to reach its limit before it acts, so on its own it would also act
/// in the transients of every scenario below base speed. A pure model misses what the
/// current loops' integrals supply (dead time, device drop, parameter errors: about 5 V
/// of 184 V measured at base speed on the paper machine), which is just the margin; at
/// no load near base speed it then kept the rated flux while the q loop was out of
/// voltage (measured: the drive stuck near 980 rpm). So: the model sets the flux where
/// the steady state needs it, and the trim corrects it from the measured voltage, both
/// only where the no-load voltage at rated flux w Ls i_sd_rated exceeds
/// [`FW_TRIM_GATE`] V.
///
/// With V = [`FW_VOLTAGE_FRACTION`] v_max and w = max(|w_s|, w_min), the steady-state
/// voltages of eq. (9a)/(9b) with lambda_r = (L_M^2/L_R) i_sd, neglecting R in the d axis,
/// are v_sd = -sigma Ls w_s i_sq, v_sq = Rs i_sq + w_s Ls i_sd (+ the q loop's integral
/// I_q, measured). Keeping |v| <= V gives the model flux current
///
/// ```text
/// i_sd_model = (sqrt(max(V^2 - (w sigmaLs i_sq)^2, V^2/2)) - (Rs i_sq + I_q) sgn w_s)/(w Ls)
/// ```
///
/// (the square root floored at V/sqrt 2: at most half the voltage squared goes to the q
/// current). The trim integrates (|v*|^2 - V_t^2)/v_max / w with V_t = [`FW_TRIM_FRACTION`]
/// v_max at [`FW_TRIM_BANDWIDTH`], kept >= 0, and
/// `i_sd* = clamp(min(i_sd_model, i_sd_rated - trim), i_sd_min, i_sd_rated)`.
///
/// The torque current is limited by the current circle sqrt(I_max^2 - i_sd*^2)
/// (constant-power region) and by the maximum-torque-per-voltage line (breakdown
/// region): with v_sq ~ Rs i_sq + w Ls i_sd and v_sd ~ -w sigma Ls i_sq, the product
/// i_sd i_sq on |v| = V is largest at i_sq/i_sd = w Ls/|Rs + j w sigma Ls|. While
/// i_sd* is the rated flux current the limits are the design's static ones (the control
/// below base speed is unchanged). i_sq in the model is the previous step's reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldWeakeningDesign<N: Num = f32> {
    /// Field weakening on ([`FieldWeakeningSettings::enabled`](crate::FieldWeakeningSettings::enabled)).
    pub enabled: bool,
    /// [`FW_VOLTAGE_FRACTION`] (dimensionless): V = this x v_max.
    pub voltage_fraction: N::Gain,
    /// w_min, rad/s electrical (> 0): the floor of |w_s| as divisor.
    pub min_frequency: N,
    /// i_sd_min, A.
    pub min_flux_current: N,
    /// I_max, A.
    pub current_limit: N,
    /// 1/Ls: flux linkage (V per rad/s) -> current, 1/H.
    pub inv_stator_inductance: N::Gain,
    /// Ls: (rad/s electrical x A) -> V, H.
    pub stator_inductance: N::Gain,
    /// 1: (rad/s electrical x Wb) -> V, for w lambda_r.
    pub flux_voltage: N::Gain,
    /// Voltage-feedback trim gain [`FW_TRIM_BANDWIDTH`] Ts / (2 gamma Ls): flux linkage
    /// excess (V per rad/s) -> i_sd* change per step, 1/H.
    pub trim_gain: N::Gain,
    /// [`FW_TRIM_GATE`] (dimensionless): the trim acts only where w Ls i_sd_rated is
    /// above this fraction of V.
    pub trim_gate: N::Gain,
    /// [`FW_TRIM_FRACTION`] (dimensionless): the trim holds |v*| at this fraction of
    /// v_max.
    pub trim_fraction: N::Gain,
    /// Ls i_sd_rated, Wb (the stator flux linkage at rated flux, no load).
    pub rated_linkage: N,
    /// lambda_ref, Wb: the orientation correction's gain k/lambda_ref is rescaled by
    /// lambda_ref/lambda_r while the flux is weakened.
    pub flux_reference: N,
    /// Over-voltage control on ([`FieldWeakeningSettings::overvoltage_control`](crate::FieldWeakeningSettings::overvoltage_control)).
    pub overvoltage_control: bool,
    /// Light-load flux optimisation on ([`FieldWeakeningSettings::flux_optimisation`](crate::FieldWeakeningSettings::flux_optimisation)).
    pub flux_optimisation: bool,
    /// sqrt((Rs + R_R) / Rs): the copper-loss optimum's i_sd / |i_sq|.
    pub optimum_ratio: N::Gain,
    /// The optimiser's floor, A ([`FLUX_OPT_MIN_FRACTION`] flux_current).
    pub optimum_min_current: N,
    /// Ts / ([`FLUX_OPT_FALL_TAU_R`] tau_r): the optimum's fall per step.
    pub optimum_fall: N::Gain,
    /// Bus voltage where the regenerative current starts to be reduced, V.
    pub regen_start: N,
    /// 1/(bus band over which it falls to zero), 1/V.
    pub inv_regen_band: N::Gain,
}

impl FieldWeakeningDesign {
    /// The design for the settings `cfg` with the base speed `base_speed` (rad/s
    /// mechanical: the no-load speed the linear voltage limit reaches at `dc_bus_max`),
    /// updated every `ts` (s, the slow period).
    pub fn new(cfg: &DriveConfig, base_speed: f32, ts: f32) -> Self {
        let m = cfg.machine;
        let band = (OVC_END_FRACTION - OVC_START_FRACTION) * cfg.limits.dc_bus_max;
        Self {
            enabled: cfg.field_weakening.enabled,
            voltage_fraction: FW_VOLTAGE_FRACTION,
            min_frequency: FW_MIN_FREQUENCY_FRACTION * m.pole_pairs_f32() * base_speed,
            min_flux_current: FW_MIN_FLUX_FRACTION * cfg.loops.flux_current,
            current_limit: cfg.limits.current_limit,
            inv_stator_inductance: 1.0 / m.stator_inductance(),
            stator_inductance: m.stator_inductance(),
            flux_voltage: 1.0,
            trim_gain: FW_TRIM_BANDWIDTH * ts / (2.0 * FW_VOLTAGE_FRACTION * m.stator_inductance()),
            trim_gate: FW_TRIM_GATE,
            trim_fraction: FW_TRIM_FRACTION,
            rated_linkage: m.stator_inductance() * cfg.loops.flux_current,
            flux_reference: m.rotor_flux_for(cfg.loops.flux_current),
            overvoltage_control: cfg.field_weakening.overvoltage_control,
            flux_optimisation: cfg.field_weakening.flux_optimisation,
            optimum_ratio: sqrt(
                (m.stator_resistance() + m.referred_rotor_resistance()) / m.stator_resistance(),
            ),
            optimum_min_current: FLUX_OPT_MIN_FRACTION * cfg.loops.flux_current,
            optimum_fall: (ts / (FLUX_OPT_FALL_TAU_R * m.rotor_time_constant())).min(1.0),
            regen_start: OVC_START_FRACTION * cfg.limits.dc_bus_max,
            inv_regen_band: 1.0 / band,
        }
    }
}

/// The machine-model constants and last-period signals the field weakening reads, with
/// this step's estimates. Units as in [`FieldWeakeningDesign`] (SI in f32, per unit in
/// fixed point).
#[derive(Clone, Copy, Debug)]
pub struct FieldWeakeningInputs<N: Num> {
    /// Rated flux current i_sd_rated, A (the design's i_sd*).
    pub flux_current: N,
    /// sigma Ls: (frequency x current) -> voltage.
    pub transient_inductance: N::Gain,
    /// The torque-current limits below base speed (the speed PI's range), A.
    pub torque_current_min: N,
    /// ... upper.
    pub torque_current_max: N,
    /// Stator frequency w_s, rad/s electrical (this step's estimate).
    pub stator_frequency: N,
    /// Rs_hat, ohm.
    pub stator_resistance: N,
    /// Omega_hat, rad/s mechanical (the regenerative side's sign).
    pub speed: N,
    /// DC bus, V.
    pub dc_bus: N,
    /// The current loops' voltage limit this step.
    pub limit: VoltageLimit<N>,
    /// z^-1: the voltage command of the last step (rotor-flux frame), V.
    pub last_voltage: Dq<N>,
    /// z^-1: the last step's torque-current reference i_sq*, A.
    pub last_torque_current: N,
    /// z^-1: the q current loop's integral after the last step (the voltage the model
    /// misses), V.
    pub q_integral: N,
    /// z^-1: the q current loop was at its voltage limit in the last step.
    pub q_saturated: bool,
    /// The rotor flux is within tolerance of its reference (this step).
    pub flux_settled: bool,
}

/// The field weakening's output: the flux-current reference and the torque-current
/// limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldWeakeningOutput<N> {
    /// i_sd*, A.
    pub i_sd_ref: N,
    /// Lower i_sq* limit, A.
    pub i_sq_min: N,
    /// Upper i_sq* limit, A.
    pub i_sq_max: N,
    /// The torque limit is set by the voltage or the bus, not the current circle.
    pub torque_limited: bool,
}

/// The field weakening's state: the voltage-feedback trim, the flux optimiser's i_sd*
/// and the latch that tells the estimators the flux is moving.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FieldWeakening<N> {
    /// The voltage-feedback trim of i_sd*, A (>= 0).
    trim: N,
    /// The light-load flux optimiser's i_sd*, A (rated when off).
    flux_optimum: N,
    /// Field weakening has moved the flux and it has not settled back at its rated value
    /// yet.
    active: bool,
}

impl<N: Num + DivSqrt> FieldWeakening<N> {
    /// The state of a start: no trim, the optimiser at the rated flux current
    /// `flux_current` (A).
    pub fn new(flux_current: N) -> Self {
        Self {
            trim: N::ZERO,
            flux_optimum: flux_current,
            active: false,
        }
    }

    /// Whether the flux is weakened or has not settled back at its rated value since: the
    /// estimators then take the moving flux into account (read after [`Self::update`],
    /// this step's; before it, the last step's).
    #[inline(always)]
    pub fn active(&self) -> bool {
        self.active
    }

    /// One step: the flux current i_sd* and the torque-current limits at this step's
    /// stator frequency, bus and load ([`FieldWeakeningDesign`] for the equations), the
    /// flux optimiser's i_sd* below them when on, and the latch. Below base speed (i_sd*
    /// at its rated value) and off the bus limit it returns the static values unchanged.
    #[inline(always)]
    pub fn update(
        &mut self,
        cfg: &FieldWeakeningDesign<N>,
        x: &FieldWeakeningInputs<N>,
    ) -> FieldWeakeningOutput<N> {
        let mut out = self.limits(cfg, x);
        if cfg.flux_optimisation {
            // off by default: cold, so that the default falls through
            core::hint::cold_path();
            out.i_sd_ref = self.flux_optimum(cfg, x.last_torque_current, out.i_sd_ref);
        }
        // latched from the first weakened step until the flux is back at its rated value
        self.active = out.i_sd_ref < x.flux_current || (self.active && !x.flux_settled);
        out
    }

    /// Light-load flux optimisation ([`FieldWeakeningSettings::flux_optimisation`](crate::FieldWeakeningSettings::flux_optimisation)): the
    /// copper-loss optimum i_sd* = sqrt((Rs + R_R)/Rs) |i_sq*| of the last step's torque
    /// current `i_sq_ref` (A), between the floor and `i_sd_max` (the rated or weakened
    /// flux current). It rises at once (a load step takes the flux back up, with tau_r)
    /// and falls slowly: with the lower flux the same torque needs more i_sq, so the
    /// optimum found from i_sq is approached from above, where that loop settles.
    #[inline(never)]
    fn flux_optimum(&mut self, fw: &FieldWeakeningDesign<N>, i_sq_ref: N, i_sd_max: N) -> N {
        let target = N::gain(fw.optimum_ratio, i_sq_ref.abs());
        let target = target.clamp(fw.optimum_min_current, i_sd_max);
        self.flux_optimum = if target > self.flux_optimum {
            target
        } else {
            self.flux_optimum + N::gain(fw.optimum_fall, target - self.flux_optimum)
        };
        if self.flux_optimum < i_sd_max {
            self.flux_optimum
        } else {
            i_sd_max
        }
    }

    /// Field weakening and over-voltage control: the model flux current with its
    /// voltage-feedback trim, the current circle and the maximum-torque-per-voltage line,
    /// and the regenerative side's fold-back above the bus threshold.
    #[inline(always)]
    fn limits(
        &mut self,
        fw: &FieldWeakeningDesign<N>,
        x: &FieldWeakeningInputs<N>,
    ) -> FieldWeakeningOutput<N> {
        let i_sd_rated = x.flux_current;
        let limit = x.limit;
        let mut out = FieldWeakeningOutput {
            i_sd_ref: i_sd_rated,
            i_sq_min: x.torque_current_min,
            i_sq_max: x.torque_current_max,
            torque_limited: false,
        };
        if fw.enabled {
            let ws = x.stator_frequency;
            // |w_s| floored at w_min > 0: the divisor cannot vanish
            let w = ws.abs();
            let w = if w > fw.min_frequency {
                w
            } else {
                fw.min_frequency
            };
            let v = N::gain(fw.voltage_fraction, limit.steady);
            // field weakening is evaluated only where the no-load voltage at rated flux
            // w Ls i_sd_rated exceeds FW_TRIM_GATE V (or the trim has not decayed yet): below
            // that the rated flux is kept without computing the model (the cheap path)
            let near_base =
                N::gain_mul(fw.flux_voltage, w, fw.rated_linkage) > N::gain(fw.trim_gate, v);
            let i_d_v = if near_base || self.trim > N::ZERO {
                let v2 = v * v;
                let iq = x.last_torque_current;
                // q-axis share of the voltage at the present load, floored at the
                // maximum-torque-per-voltage split (half of V^2 each)
                let xq = N::gain_mul(x.transient_inductance, w, iq);
                let rest = v2 - xq * xq;
                let half = v2.half();
                let budget = if rest > half { rest } else { half };
                // Rs i_sq adds to v_sq when it has the sign of w_s (motoring), and so does the
                // q current loop's integral: the voltage the model misses (dead time, device
                // drop, parameter errors), measured
                let drop = x.stator_resistance * iq + x.q_integral;
                let drop = if ws < N::ZERO { -drop } else { drop };
                // the rated flux fits when sqrt(budget) - drop >= w Ls i_sd_rated: decided
                // without the square root and the division (the cheap path below base speed)
                let need = N::gain_mul(fw.stator_inductance, w, i_sd_rated) + drop;
                let i_d_model = if need <= N::ZERO || need * need <= budget {
                    i_sd_rated
                } else {
                    N::gain(fw.inv_stator_inductance, N::ratio(budget.sqrt() - drop, w))
                };
                // voltage-feedback trim of what the model misses (the current loops'
                // integrals, parameter errors): integrates (|v*|^2 - V_t^2)/v_max
                // ~ 2 (|v*| - V_t) of the last command (V_t = trim fraction x the steady
                // voltage; with overmodulation v_max is 3.5 % above V_t / 0.92 and the
                // loop gain that much lower), per flux linkage (/w), kept >= 0,
                // only where the rated flux needs most of V (`near_base`), so that faults
                // below base speed do not move the flux; elsewhere it only decays
                let trim = {
                    let va = x.last_voltage;
                    let vt = N::gain(fw.trim_fraction, limit.steady);
                    let excess = (va.d * va.d + va.q * va.q - vt * vt) * limit.inv_max;
                    let excess = if near_base { excess } else { -excess.abs() };
                    let trim = self.trim + N::gain(fw.trim_gain, N::ratio(excess, w));
                    trim.clamp(N::ZERO, i_sd_rated - fw.min_flux_current)
                };
                self.trim = trim;
                if i_sd_rated - trim < i_d_model {
                    i_sd_rated - trim
                } else {
                    i_d_model
                }
            } else {
                i_sd_rated
            };
            let i_d = i_d_v.clamp(fw.min_flux_current, i_sd_rated);
            if i_d < i_sd_rated {
                // constant-power / breakdown region: the current circle with the lower
                // flux current, and the maximum-torque-per-voltage bound below;
                // the voltage itself is shared by the current loops (d priority) and
                // the trim above lowers the flux while the q loop is short of voltage
                let circle = (fw.current_limit * fw.current_limit - i_d * i_d).sqrt();
                // maximum torque per voltage at this flux current: with
                // v_sq ~ Rs i_sq + w Ls i_sd and v_sd ~ -w sigma Ls i_sq, the product
                // i_sd i_sq on |v| = V is largest at i_sq/i_sd = w Ls/|Rs + j w sigma Ls|;
                // beyond it more i_sq (and the lower flux the trim then needs) lowers the
                // torque, so the trim settles on that line instead of the flux floor
                let x_q = N::gain_mul(x.transient_inductance, w, N::ONE);
                let rs = x.stator_resistance;
                let z_q = (x_q * x_q + rs * rs).sqrt();
                let mtpv = N::ratio(N::gain_mul(fw.stator_inductance, w, i_d), z_q);
                let i_q = if mtpv < circle { mtpv } else { circle };
                out.i_sd_ref = i_d;
                out.i_sq_min = -i_q;
                out.i_sq_max = i_q;
                out.torque_limited = mtpv < circle || x.q_saturated;
            }
        }
        if fw.overvoltage_control && x.dc_bus > fw.regen_start {
            // (braking with the bus high: marked cold)
            core::hint::cold_path();
            // over-voltage control: the regenerative side (i_sq against the speed) falls
            // linearly to zero over the band above regen_start
            let k = (N::ONE - N::gain(fw.inv_regen_band, x.dc_bus - fw.regen_start))
                .clamp(N::ZERO, N::ONE);
            if x.speed > N::ZERO {
                out.i_sq_min = out.i_sq_min * k;
            } else {
                out.i_sq_max = out.i_sq_max * k;
            }
            out.torque_limited = true;
        }
        out
    }
}

impl FieldWeakeningDesign<f32> {
    /// This design in the arithmetic `N` with the bases `b`: voltages of V_base, currents
    /// of I_base, frequencies of w_base; flux linkage V/w comes out of the ratio in
    /// V_base/w_base. The frequency floor must be inside the reciprocal's domain. Fails
    /// naming the setting the value depends on.
    pub fn convert<N: Num + Units>(
        &self,
        b: &PerUnitBases,
    ) -> Result<FieldWeakeningDesign<N>, &'static str> {
        if self.min_frequency / b.frequency < N::RECIP_FLOOR {
            return Err("limits.max_speed");
        }
        let g = crate::num::gain_in::<N>;
        let pu =
            |x: f32, base: f32, field: &'static str| N::checked_from_f32(x / base).ok_or(field);
        Ok(FieldWeakeningDesign {
            enabled: self.enabled,
            voltage_fraction: g(self.voltage_fraction, "field_weakening")?,
            min_frequency: pu(self.min_frequency, b.frequency, "limits.max_speed")?,
            min_flux_current: pu(self.min_flux_current, b.current, "loops.flux_current")?,
            current_limit: pu(self.current_limit, b.current, "limits.current_limit")?,
            inv_stator_inductance: g(
                self.inv_stator_inductance * b.voltage / (b.frequency * b.current),
                "machine",
            )?,
            stator_inductance: g(
                self.stator_inductance * b.frequency * b.current / b.voltage,
                "machine",
            )?,
            flux_voltage: g(
                self.flux_voltage * b.frequency * b.flux / b.voltage,
                "machine",
            )?,
            trim_gain: g(
                self.trim_gain * b.voltage / (b.frequency * b.current),
                "field_weakening",
            )?,
            trim_gate: g(self.trim_gate, "field_weakening")?,
            trim_fraction: g(self.trim_fraction, "field_weakening")?,
            rated_linkage: pu(self.rated_linkage, b.flux, "loops.flux_current")?,
            flux_reference: pu(self.flux_reference, b.flux, "loops.flux_current")?,
            overvoltage_control: self.overvoltage_control,
            flux_optimisation: self.flux_optimisation,
            optimum_ratio: g(self.optimum_ratio, "machine")?,
            optimum_min_current: pu(self.optimum_min_current, b.current, "loops.flux_current")?,
            optimum_fall: g(self.optimum_fall, "machine")?,
            regen_start: pu(self.regen_start, b.voltage, "limits.dc_bus_max")?,
            inv_regen_band: g(self.inv_regen_band * b.voltage, "limits.dc_bus_max")?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::{DriveConfig, DriveDesign};
    use crate::svpwm::linear_limit;

    fn design(overvoltage: bool) -> DriveDesign {
        let mut cfg = DriveConfig::paper_defaults();
        cfg.field_weakening.overvoltage_control = overvoltage;
        DriveDesign::new(cfg).unwrap()
    }

    fn inputs(d: &DriveDesign, ws: f32, dc_bus: f32, settled: bool) -> FieldWeakeningInputs<f32> {
        let v = linear_limit(dc_bus) * 0.98;
        FieldWeakeningInputs {
            flux_current: d.cascade.i_sd_ref,
            transient_inductance: d.model.transient_inductance,
            torque_current_min: d.speed_loop.pi.out_min,
            torque_current_max: d.speed_loop.pi.out_max,
            stator_frequency: ws,
            stator_resistance: d.config.machine.stator_resistance(),
            speed: ws / d.pole_pairs,
            dc_bus,
            limit: VoltageLimit {
                max: v,
                inv_max: 1.0 / v,
                steady: v,
                sustained: v,
                inv_sustained: 1.0 / v,
            },
            last_voltage: Dq { d: 0.0, q: 0.9 * v },
            last_torque_current: 1.0,
            q_integral: 0.0,
            q_saturated: false,
            flux_settled: settled,
        }
    }

    #[test]
    fn below_base_speed_the_static_limits_pass_unchanged() {
        let d = design(false);
        let mut fw = FieldWeakening::new(d.cascade.i_sd_ref);
        let out = fw.update(
            &d.field_weakening,
            &inputs(&d, 50.0, d.config.limits.dc_bus_max, true),
        );
        assert_eq!(out.i_sd_ref, d.cascade.i_sd_ref);
        assert_eq!(
            (out.i_sq_min, out.i_sq_max),
            (d.speed_loop.pi.out_min, d.speed_loop.pi.out_max)
        );
        assert!(!out.torque_limited && !fw.active());
    }

    #[test]
    fn beyond_base_speed_the_flux_falls_inside_the_current_circle_and_latches() {
        let d = design(false);
        let mut fw = FieldWeakening::new(d.cascade.i_sd_ref);
        let base = linear_limit(d.config.limits.dc_bus_max) / d.flux_reference;
        let out = fw.update(
            &d.field_weakening,
            &inputs(&d, 2.0 * base, d.config.limits.dc_bus_max, true),
        );
        assert!(
            out.i_sd_ref < d.cascade.i_sd_ref && out.i_sd_ref >= d.field_weakening.min_flux_current
        );
        let i_max = d.field_weakening.current_limit;
        assert!(out.i_sd_ref.powi(2) + out.i_sq_max.powi(2) <= i_max * i_max * 1.0001);
        assert!(fw.active());
        // back below base speed: latched until the flux has settled at its rated value
        let low = inputs(&d, 50.0, d.config.limits.dc_bus_max, false);
        fw.update(&d.field_weakening, &low);
        assert!(fw.active());
        fw.update(
            &d.field_weakening,
            &FieldWeakeningInputs {
                flux_settled: true,
                ..low
            },
        );
        assert!(!fw.active());
    }

    #[test]
    fn over_voltage_control_folds_back_the_regenerative_side_only() {
        let d = design(true);
        let f = &d.field_weakening;
        let mut fw = FieldWeakening::new(d.cascade.i_sd_ref);
        let mid = f.regen_start + 0.5 / f.inv_regen_band;
        let x = inputs(&d, 50.0, mid, true);
        let out = fw.update(f, &x);
        // turning forward: the braking (negative) side halves, the motoring side stays
        assert!((out.i_sq_min - 0.5 * x.torque_current_min).abs() < 1e-3 * x.torque_current_max);
        assert_eq!(out.i_sq_max, x.torque_current_max);
        assert!(out.torque_limited);
        let reverse = fw.update(
            f,
            &FieldWeakeningInputs {
                speed: -x.speed,
                ..x
            },
        );
        assert_eq!(reverse.i_sq_min, x.torque_current_min);
        assert!(
            (reverse.i_sq_max - 0.5 * x.torque_current_max).abs() < 1e-3 * x.torque_current_max
        );
    }
}
