//! The current sensors' relative gain, identified while magnetizing at rest (the
//! far side's ripple).
//!
//! ## Why
//!
//! Two current channels whose gains differ (the paper's experiments: +0.3 % and -0.3 %)
//! make the measured current a rotated, unequally scaled copy of the true one: the
//! current loops, which regulate the measured current, put a negative-sequence current
//! into the machine. In the rotating frame it is a ripple at twice the stator frequency,
//! and at low stator frequency that is inside the speed observer's band. Measured on the
//! far side of the unobservable line (60 rpm, 4.5 N m regenerating, f_s = -1.05 Hz, no
//! regeneration limit): -4.62 rpm of estimation error with the speed swinging 0.7-127 rpm,
//! against -0.75 rpm and 51-72 rpm with equal gains (docs/robustness.md).
//!
//! ## How (two-phase sensing, phases a and b measured)
//!
//! While magnetizing at rest the frame is held at angle 0: the d axis is phase a, the q
//! axis is beta. The current loops make the *measured* beta current zero, i.e. the
//! measured b sample -a/2. With channel gains g_a and g_b, the true currents are then
//! `a_m / g_a` and `-a_m / (2 g_b)`, and the true beta current is
//!
//! ```text
//! i_beta / i_alpha = (1 - g_a / g_b) / sqrt(3) = eps.
//! ```
//!
//! That current flows at zero frequency: its voltage is the stator resistance's plus the
//! rotor's while the rotor flux along beta builds (the same first-order dynamics as the
//! d axis, from zero), and the inverter's error is along alpha (phase a carries +I, b and
//! c carry the same -I/2, so their voltage errors are equal). So at every step
//!
//! ```text
//! v_beta = eps (R_s i_d + R_R i_d - lambda_R / tau_r)
//! ```
//!
//! (inverse-Gamma model: R_R i_d - lambda_R / tau_r is d lambda_R / dt) with the bracket
//! the d-axis voltage the flux model predicts without the inverter's error. The drive
//! low-passes v_beta (the q-axis voltage it applied, less Rs_hat times the measured beta
//! current, which the loops hold near zero) and the bracket with
//! one filter, from the first magnetizing step: a linear filter keeps their ratio, so the
//! ratio is `eps` through the flux build-up and the inverter test's levels alike. At the
//! handover to running, with the standstill identification's R_s_hat,
//!
//! ```text
//! k = g_a / g_b = 1 - sqrt(3) eps,
//! ```
//!
//! the ratio the samples are corrected by from then on (after the offsets are
//! subtracted): a by `(1 + 1/k) / 2` and b by `(1 + k) / 2`. Their ratio is k, and their
//! mean gain `(g_a + g_b) / 2` is kept: that is the current scale every other part of
//! the drive was tuned and identified with (this test cannot see the absolute scale, and
//! moving it by the mismatch's half moves the running Rs estimate: at 500 rpm by -1.7 %
//! when b alone was scaled). The next start measures what is left and multiplies it
//! in, so the ratio converges across starts. It is clamped to
//! [`GAIN_CALIBRATION_LIMIT`].
//!
//! Precision: an offset error on b also makes a DC beta current, read as a gain error of
//! `2 delta_b / i_d`. With the idle offset measurement's 0.45 mA (10 mA of noise averaged
//! over 0.1 s) and 1.5 A of flux current, k scatters by about 0.06 % over noise
//! realizations (measured: 1.0044-1.0065 for a true 1.0060, docs/robustness.md).
//!
//! Not on a flying start (the frame turns), not with three-phase sensing (one ratio out of
//! two), and off in the paper's scheme (figs. 6-12).

use crate::num::DivSqrt;
use crate::num::FineIntegrator;
use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;

/// The filter's time constant, s: longer than any magnetizing (0.4-1 s), so that the
/// filter is nearly a plain sum of every step's sample scaled by `Ts / tau` (bounded like
/// the samples): the ratio is exact for any linear filter, and the even weights average the
/// most noise.
pub const GAIN_CALIBRATION_FILTER_TIME: f32 = 2.0;
/// The shortest magnetizing whose ratio is taken, s.
pub const GAIN_CALIBRATION_MIN_TIME: f32 = 0.2;
/// The largest correction |k - 1| applied (5 %: current sensors are specified to about
/// 1 %; a larger estimate is clamped, not trusted).
pub const GAIN_CALIBRATION_LIMIT: f32 = 0.05;
/// The filtered model voltage must reach this fraction of what [`GAIN_CALIBRATION_MIN_TIME`]
/// of the nominal `R_s i_d` gives it for the ratio to be taken: a magnetizing cut short
/// leaves the correction as it was.
pub const GAIN_CALIBRATION_MIN_FRACTION: f32 = 0.5;

/// The calibration's design (immutable; [`crate::design::DriveDesign`] builds it).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GainCalibrationConfig<N: Num + FineIntegrator = f32> {
    /// Calibrate at all: [`StartSettings::current_gain_calibration`](crate::StartSettings::current_gain_calibration) with
    /// two-phase sensing.
    pub enabled: bool,
    /// The low-pass gain, `Ts / GAIN_CALIBRATION_FILTER_TIME` (fixed point: into the finer
    /// integrator format, whose resolution keeps a step's increment, `Ts / tau` of a
    /// 50 mV signal, from rounding to nothing).
    pub filter: N::Gain,
    /// The filters' bounds (the finer format's range; unbounded in f32), V.
    pub fine_bounds: (N::Fine, N::Fine),
    /// The smallest filtered model voltage whose ratio is taken, V:
    /// [`GAIN_CALIBRATION_MIN_FRACTION`] of the nominal `R_s i_d` over
    /// [`GAIN_CALIBRATION_MIN_TIME`], `R_s i_d MIN_TIME / tau` (the filter's sum).
    pub min_voltage: N,
    /// Both filtered voltages are scaled by this before their ratio (dimensionless; 1 in
    /// f32; in fixed point it brings `min_voltage` to 0.5 pu, so that the divisor's
    /// reciprocal stays within the format).
    pub ratio_scale: N::Gain,
    /// sqrt(3) (dimensionless).
    pub sqrt3: N::Gain,
    /// Bounds of the correction k, `1 -/+ GAIN_CALIBRATION_LIMIT`.
    pub bounds: (N, N),
}

impl GainCalibrationConfig<f32> {
    /// The design for period `ts` (s), the nominal stator resistance `rs` (ohm) and the
    /// flux current `i_d` (A).
    pub fn new(enabled: bool, ts: f32, rs: f32, i_d: f32) -> Self {
        Self {
            enabled,
            filter: ts / GAIN_CALIBRATION_FILTER_TIME,
            fine_bounds: (f32::MIN, f32::MAX),
            min_voltage: GAIN_CALIBRATION_MIN_FRACTION * rs * i_d * GAIN_CALIBRATION_MIN_TIME
                / GAIN_CALIBRATION_FILTER_TIME,
            ratio_scale: 1.0,
            sqrt3: 1.732_050_8,
            bounds: (1.0 - GAIN_CALIBRATION_LIMIT, 1.0 + GAIN_CALIBRATION_LIMIT),
        }
    }
}

/// The calibration's state: the correction in use and the two filtered voltages of the
/// magnetizing under way.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GainCalibration<N: Num + FineIntegrator = f32> {
    /// k = g_a / g_b as calibrated (1 until a calibration).
    pub ratio: N,
    /// The factors on the a and b samples, `(1 + 1/k) / 2` and `(1 + k) / 2`.
    pub factors: [N; 2],
    /// Low-passed beta (held q-axis) voltage, V (in the finer format).
    voltage: N::Fine,
    /// Low-passed model d-axis voltage, V (module docs; in the finer format).
    model: N::Fine,
    /// The magnetizing under way can be used (frame held since its start).
    usable: bool,
}

impl<N: Num + DivSqrt + FineIntegrator + DivSqrt + FineIntegrator> Default for GainCalibration<N> {
    fn default() -> Self {
        Self {
            ratio: N::ONE,
            factors: [N::ONE; 2],
            voltage: N::to_fine(N::ZERO),
            model: N::to_fine(N::ZERO),
            usable: false,
        }
    }
}

impl<N: Num + DivSqrt + FineIntegrator + DivSqrt + FineIntegrator> GainCalibration<N> {
    /// A magnetizing starts: the filters from zero (the flux builds from zero too).
    #[inline(always)]
    pub fn restart(&mut self, c: &GainCalibrationConfig<N>) {
        self.voltage = N::to_fine(N::ZERO);
        self.model = N::to_fine(N::ZERO);
        self.usable = c.enabled;
    }

    /// The frame stopped being held (a flying start): nothing to take this time.
    #[inline(always)]
    pub fn abandon(&mut self) {
        self.usable = false;
    }

    /// One magnetizing step with the frame held: `v_q` the q-axis (beta) voltage applied
    /// over the period the samples close less Rs_hat times the measured q current, `model` the d-axis voltage of the module docs'
    /// bracket, V.
    #[inline(always)]
    pub fn update(&mut self, c: &GainCalibrationConfig<N>, v_q: N, model: N) {
        if self.usable {
            let (lo, hi) = c.fine_bounds;
            let e = v_q - N::from_fine(self.voltage);
            self.voltage = N::fine_step(self.voltage, c.filter, e, true, lo, hi).0;
            let e = model - N::from_fine(self.model);
            self.model = N::fine_step(self.model, c.filter, e, true, lo, hi).0;
        }
    }

    /// The handover to running: the ratio taken into the correction (module docs) if the
    /// magnetizing was usable and long enough. Returns whether it was.
    #[inline(always)]
    pub fn finish(&mut self, c: &GainCalibrationConfig<N>) -> bool {
        let model = N::from_fine(self.model);
        let used = self.usable && model > c.min_voltage;
        if used {
            // the model voltage is at least min_voltage > 0: no vanishing divisor
            let eps = N::ratio(
                N::gain(c.ratio_scale, N::from_fine(self.voltage)),
                N::gain(c.ratio_scale, model),
            );
            let k = self.ratio - self.ratio * N::gain(c.sqrt3, eps);
            let k = k.clamp(c.bounds.0, c.bounds.1);
            self.ratio = k;
            // k within 1 -/+ 5 %: its reciprocal is bounded
            self.factors = [(N::ONE + k.recip()).half(), (N::ONE + k).half()];
        }
        self.usable = false;
        used
    }
}

impl GainCalibrationConfig<f32> {
    /// This design in the arithmetic `N` with the bases `b`: the filter into the finer
    /// integrator format over the whole of its range; where the reciprocal has a floor
    /// (fixed point) the ratio's scale brings `min_voltage` to 0.5. Fails naming the
    /// setting the value depends on.
    pub fn convert<N: Num + Units + FineIntegrator>(
        &self,
        b: &PerUnitBases,
    ) -> Result<GainCalibrationConfig<N>, &'static str> {
        let g = crate::num::gain_in::<N>;
        Ok(GainCalibrationConfig {
            enabled: self.enabled,
            filter: g(self.filter * N::FINE_SCALE, "loops.control_period")?,
            fine_bounds: N::FINE_RANGE,
            min_voltage: N::checked_from_f32(self.min_voltage / b.voltage)
                .ok_or("loops.flux_current")?,
            ratio_scale: g(
                if N::RECIP_FLOOR > 0.0 {
                    0.5 * b.voltage / self.min_voltage
                } else {
                    self.ratio_scale
                },
                "start.current_gain_calibration",
            )?,
            sqrt3: g(self.sqrt3, "start.current_gain_calibration")?,
            // dimensionless
            bounds: (N::from_f32(self.bounds.0), N::from_f32(self.bounds.1)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The held-frame relation of the module docs, closed: channel b reads `g_b` of its
    /// current; the loops make the measured beta zero; the beta voltage is `eps` times the
    /// model voltage. Two starts bring k to g_a / g_b.
    #[test]
    fn converges_to_the_channel_ratio() {
        let c = GainCalibrationConfig::new(true, 2e-4, 8.0, 2.0);
        let (g_a, g_b) = (1.003_f32, 0.997_f32);
        let mut cal = GainCalibration::<f32>::default();
        for _ in 0..2 {
            cal.restart(&c);
            // corrected a = f_a g_a i_a and b = f_b g_b i_b; the loops hold the
            // corrected measured beta at zero: f_b g_b i_b = -f_a g_a i_a / 2
            let [f_a, f_b] = cal.factors;
            let i_a = 2.0 / (f_a * g_a);
            let i_b = -f_a * g_a * i_a / (2.0 * f_b * g_b);
            let i_beta = (i_a + 2.0 * i_b) / 1.732_050_8;
            let model = 8.0 * 2.0;
            for _ in 0..5000 {
                cal.update(&c, 8.0 * i_beta, model);
            }
            assert!(cal.finish(&c));
        }
        let k = cal.ratio;
        assert!((k - g_a / g_b).abs() < 2e-5, "k {k}");
        // the mean gain kept
        let [f_a, f_b] = cal.factors;
        assert!((f_a * g_a + f_b * g_b - (g_a + g_b)).abs() < 1e-5);
        assert!((f_b / f_a - k).abs() < 1e-5);
    }

    #[test]
    fn a_short_or_unheld_magnetizing_leaves_the_correction() {
        let c = GainCalibrationConfig::new(true, 2e-4, 8.0, 2.0);
        let mut cal = GainCalibration::<f32>::default();
        cal.restart(&c);
        for _ in 0..10 {
            cal.update(&c, 0.1, 16.0);
        }
        assert!(!cal.finish(&c), "too short");
        cal.restart(&c);
        for _ in 0..5000 {
            cal.update(&c, 0.1, 16.0);
        }
        cal.abandon();
        assert!(!cal.finish(&c), "abandoned");
        assert_eq!(cal.ratio, 1.0);
        assert_eq!(cal.factors, [1.0; 2]);
        let off = GainCalibrationConfig::new(false, 2e-4, 8.0, 2.0);
        cal.restart(&off);
        for _ in 0..5000 {
            cal.update(&off, 0.1, 16.0);
        }
        assert!(!cal.finish(&off), "disabled");
    }

    #[test]
    fn the_correction_is_clamped() {
        let c = GainCalibrationConfig::new(true, 2e-4, 8.0, 2.0);
        let mut cal = GainCalibration::<f32>::default();
        cal.restart(&c);
        for _ in 0..5000 {
            cal.update(&c, 4.0, 16.0);
        }
        assert!(cal.finish(&c));
        assert_eq!(cal.ratio, 1.0 - GAIN_CALIBRATION_LIMIT);
    }
}
