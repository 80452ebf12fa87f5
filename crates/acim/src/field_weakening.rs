//! Field weakening, over-voltage control and light-load flux optimisation: the flux
//! current i_sd* and the torque-current limits at this step's stator frequency, bus and
//! load ([`FieldWeakeningDesign`] for the equations).

use crate::config::DriveConfig;
use crate::math::sqrt;
use crate::num::Num;
use crate::svpwm::FW_TRIM_FRACTION;

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

/// Torque held at the voltage or bus limit: the speed reference stays within this
/// fraction of `max_speed` of the speed estimate (the reachable speed is held and
/// reported instead of a growing speed error).
pub const FW_HOLD_BAND_FRACTION: f32 = 0.01;

/// The telemetry's `speed_target_limited` stays set this many speed-loop time constants
/// after the hold last bound: the hold binds only in the steps where the speed PI sits at
/// its limit, which flickers at the reachable speed, and a report that flickers with it
/// (a third of the steps, measured) says less than it knows.
pub const FW_REPORT_SPEED_LOOP_CONSTANTS: f32 = 2.5;

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
/// current). The trim integrates (|v*|^2 - V_t^2)/v_max / w with V_t = [`FW_TRIM_FRACTION`](crate::design::FW_TRIM_FRACTION)
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
    /// Field weakening on ([`DriveConfig::field_weakening`](crate::design::DriveConfig::field_weakening)).
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
    /// Hold band, rad/s mechanical ([`FW_HOLD_BAND_FRACTION`] max_speed).
    pub hold_band: N,
    /// Steps the target stays reported as limited after the hold last bound
    /// ([`FW_REPORT_SPEED_LOOP_CONSTANTS`] / (speed bandwidth Ts)).
    pub report_steps: u32,
    /// Voltage-feedback trim gain [`FW_TRIM_BANDWIDTH`] Ts / (2 gamma Ls): flux linkage
    /// excess (V per rad/s) -> i_sd* change per step, 1/H.
    pub trim_gain: N::Gain,
    /// [`FW_TRIM_GATE`] (dimensionless): the trim acts only where w Ls i_sd_rated is
    /// above this fraction of V.
    pub trim_gate: N::Gain,
    /// [`FW_TRIM_FRACTION`](crate::design::FW_TRIM_FRACTION) (dimensionless): the trim holds |v*| at this fraction of
    /// v_max.
    pub trim_fraction: N::Gain,
    /// Ls i_sd_rated, Wb (the stator flux linkage at rated flux, no load).
    pub rated_linkage: N,
    /// lambda_ref, Wb: the orientation correction's gain k/lambda_ref is rescaled by
    /// lambda_ref/lambda_r while the flux is weakened.
    pub flux_reference: N,
    /// Over-voltage control on ([`DriveConfig::overvoltage_control`](crate::design::DriveConfig::overvoltage_control)).
    pub overvoltage_control: bool,
    /// Light-load flux optimisation on ([`DriveConfig::flux_optimisation`](crate::design::DriveConfig::flux_optimisation)).
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
    /// mechanical: the no-load speed the linear voltage limit reaches at `dc_bus_max`).
    pub fn new(cfg: &DriveConfig, base_speed: f32) -> Self {
        let m = cfg.machine;
        let band = (OVC_END_FRACTION - OVC_START_FRACTION) * cfg.dc_bus_max;
        Self {
            enabled: cfg.field_weakening,
            voltage_fraction: FW_VOLTAGE_FRACTION,
            min_frequency: FW_MIN_FREQUENCY_FRACTION * m.pole_pairs_f32() * base_speed,
            min_flux_current: FW_MIN_FLUX_FRACTION * cfg.flux_current,
            current_limit: cfg.current_limit,
            inv_stator_inductance: 1.0 / m.stator_inductance(),
            stator_inductance: m.stator_inductance(),
            flux_voltage: 1.0,
            hold_band: FW_HOLD_BAND_FRACTION * cfg.max_speed,
            report_steps: (FW_REPORT_SPEED_LOOP_CONSTANTS
                / (cfg.speed_bandwidth * cfg.control_period)) as u32,
            trim_gain: FW_TRIM_BANDWIDTH * cfg.control_period
                / (2.0 * FW_VOLTAGE_FRACTION * m.stator_inductance()),
            trim_gate: FW_TRIM_GATE,
            trim_fraction: FW_TRIM_FRACTION,
            rated_linkage: m.stator_inductance() * cfg.flux_current,
            flux_reference: m.rotor_flux_for(cfg.flux_current),
            overvoltage_control: cfg.overvoltage_control,
            flux_optimisation: cfg.flux_optimisation,
            optimum_ratio: sqrt(
                (m.stator_resistance() + m.referred_rotor_resistance()) / m.stator_resistance(),
            ),
            optimum_min_current: FLUX_OPT_MIN_FRACTION * cfg.flux_current,
            optimum_fall: (cfg.control_period / (FLUX_OPT_FALL_TAU_R * m.rotor_time_constant()))
                .min(1.0),
            regen_start: OVC_START_FRACTION * cfg.dc_bus_max,
            inv_regen_band: 1.0 / band,
        }
    }
}
