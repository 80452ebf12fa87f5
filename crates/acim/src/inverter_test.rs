//! The inverter test at start: the voltage error the configured
//! dead-time and device-drop compensation leaves, identified in the first 0.45 s of
//! magnetizing from three d-axis current levels (the analysis is on
//! [`crate::design::InverterTestDesign`]), then compensated on top of the configured part.
//!
//! The state lives in the drive and is kept across stops: each start's test measures what
//! the previous correction still leaves and adds it, so the correction follows a drifting
//! inverter from start to start. While the motor runs, the fundamental cannot split the
//! stator resistance from the inverter error at a steady operating point (both give a
//! voltage along the current, Rs |i| + (4/pi) V_e, see docs/robustness.md); the error's
//! sixth harmonic across the current can, and [`crate::inverter_tracker`] adapts the
//! correction from it (`DriveConfig.trackers.inverter_tracking`), with the running Rs estimator
//! carrying the rest as an apparent resistance.

use crate::num::Num;
use crate::num::PerUnitBases;
use crate::num::Units;

/// The inverter test's d-axis current levels, fractions of `flux_current` (rising, so
/// that the last is the magnetizing current and the flux build-up goes on from it).
pub const INVERTER_TEST_LEVELS: [f32; 3] = [0.4, 0.7, 1.0];

/// Time each level of the inverter test is held, s (three levels: 0.45 s, within the
/// 0.5 s budget of the start).
pub const INVERTER_TEST_LEVEL_TIME: f32 = 0.15;

/// The first part of each level is not measured, s (the current loop settles in a few ms;
/// the rest lets the L_sigma di/dt part of the voltage die out).
pub const INVERTER_TEST_SETTLE_TIME: f32 = 0.05;

/// Time constant of the low-pass that takes each level's mean, s (a quarter of the
/// measured 0.1 s: the mean of about the last 50 ms, 250 samples at 5 kHz).
pub const INVERTER_TEST_FILTER_TIME: f32 = 0.025;

/// The test's total time, s.
pub const INVERTER_TEST_TIME: f32 = 3.0 * INVERTER_TEST_LEVEL_TIME;

/// `flux_current` must be at least this many dead-time current bands: the lowest level
/// (0.4 of it) then puts phases b and c (-0.2 of it each) at 4 bands, where the inverter's
/// error is at its full value (the fit assumes the current-sign pattern (+, -, -)).
pub const INVERTER_TEST_MIN_BANDS: f32 = 20.0;

/// The largest correction the test applies, in duty (0.05: 10 us at 5 kHz); a fit beyond
/// it is not believed (no correction, telemetry shows none).
pub const INVERTER_TEST_MAX_DUTY: f32 = 0.05;

/// The inverter test at start ([`StartSettings::inverter_identification`](crate::StartSettings::inverter_identification)).
///
/// At rest with the frame held on phase a (angle 0), a d-axis current i puts +i in phase a
/// and -i/2 in b and c. Each leg's dead-time and device-drop error V_e opposes its current,
/// and the amplitude-invariant Clarke transform of (+V_e, -V_e, -V_e) is (4/3) V_e on alpha
/// (as in [`crate::commissioning`]'s DC steps). In the inverse-Gamma model the d-axis
/// voltage is then
///
/// v_d = Rs i + L_sigma di/dt + d lambda_R/dt + (4/3) (V_e - V_e,comp),
///
/// with d lambda_R/dt = R_R i - lambda_R / tau_r, which the drive's flux model gives.
/// Holding each level until L_sigma di/dt has died out and taking the flux model's rate
/// out of the voltage leaves y = Rs i + (4/3) dV: a straight line whose slope is Rs and
/// whose intercept is the uncompensated error dV. The flux does not need to settle, so
/// three levels take 0.45 s where the commissioning's settled DC steps take 4.8 s. The
/// fit's intercept does not depend on current-sensor gain errors (they scale i, so the
/// slope); a sensor offset o moves it by Rs o (the offsets are measured before the start).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InverterTestDesign<N: Num = f32> {
    /// Steps per level (0: no test).
    pub level_steps: u32,
    /// Steps at the start of each level that are not measured.
    pub settle_steps: u32,
    /// The d-axis current of each level, A.
    pub levels: [N; 3],
    /// How far each level's measured mean may be from its reference, A (a tenth of it:
    /// the current loop did not follow the levels otherwise, and no fit is made).
    pub tolerances: [N; 3],
    /// Low-pass coefficient of each level's mean (Ts / [`INVERTER_TEST_FILTER_TIME`]).
    pub filter: N::Gain,
    /// The least-squares line through (level_k, y_k) has the intercept sum u_k y_k with
    /// u_k = 1/3 - (L_k - L_mean) L_mean / sum (L_j - L_mean)^2 (dimensionless: the levels
    /// are fixed fractions of one current); these are (3/4) u_k, so that the sum is the
    /// leg error dV, V. The loop holds the measured current's mean at the reference, so
    /// the references stand for the currents (a sensor gain error changes the slope only).
    pub error_weights: [N::Gain; 3],
    /// The slope's weights (L_k - L_mean) / sum (L_j - L_mean)^2, 1/A: sum w_k y_k is the
    /// stator resistance the test saw, ohm (reported, and the standstill Rs
    /// identification's starting value).
    pub slope_weights: [N::Gain; 3],
    /// The plausible slope: the centre and half-width of the Rs estimator's clamps
    /// ([`crate::rs_estimator::RS_MIN_FACTOR`] to [`crate::rs_estimator::RS_MAX_FACTOR`]
    /// times the nominal Rs), ohm. A slope outside is a test that did not see the
    /// machine (outcome `Rejected`).
    pub resistance_window: (N, N),
    /// [`INVERTER_TEST_MAX_DUTY`].
    pub max_duty: N,
}

impl InverterTestDesign {
    /// The test for control period `ts` (s), flux current `i_d` (A) and nominal stator
    /// resistance `rs` (ohm); off unless `enabled`.
    pub fn new(enabled: bool, ts: f32, i_d: f32, rs: f32) -> Self {
        use crate::rs_estimator::{RS_MAX_FACTOR, RS_MIN_FACTOR};
        let levels = INVERTER_TEST_LEVELS.map(|f| f * i_d);
        let mean = (levels[0] + levels[1] + levels[2]) / 3.0;
        let spread: f32 = levels.iter().map(|l| (l - mean) * (l - mean)).sum();
        let slope_weights = levels.map(|l| (l - mean) / spread);
        Self {
            level_steps: if enabled {
                ((INVERTER_TEST_LEVEL_TIME / ts) as u32).max(3)
            } else {
                0
            },
            settle_steps: (INVERTER_TEST_SETTLE_TIME / ts) as u32,
            levels,
            tolerances: levels.map(|l| 0.1 * l),
            filter: (ts / INVERTER_TEST_FILTER_TIME).min(1.0),
            error_weights: slope_weights.map(|w| 0.75 * (1.0 / 3.0 - w * mean)),
            slope_weights,
            resistance_window: (
                0.5 * (RS_MIN_FACTOR + RS_MAX_FACTOR) * rs,
                0.5 * (RS_MAX_FACTOR - RS_MIN_FACTOR) * rs,
            ),
            max_duty: INVERTER_TEST_MAX_DUTY,
        }
    }
}

/// Where the test is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum InverterTestOutcome {
    /// No test since power-up (or the test is off).
    #[default]
    NotRun,
    /// Measuring.
    Running,
    /// Fitted and applied.
    Identified,
    /// The rotor turned (flying start): no measurement, the correction kept.
    Skipped,
    /// The levels' spread was too small, the fit out of range or not finite, or its slope
    /// (Rs) outside the Rs estimator's bounds: the correction kept.
    Rejected,
}

/// The test's state and its result.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InverterTest<N: Num = f32> {
    /// The level being measured (0..3) and the step within it.
    level: usize,
    within: u32,
    mean_current: N,
    mean_voltage: N,
    points: [(N, N); 3],
    /// The voltage error per leg beyond the configured compensation, as a duty (V / V_dc):
    /// added to the configured dead-time duty (0 until a test identified one).
    pub correction_duty: N,
    /// The last fit's slope, the stator resistance the test saw, ohm (0 before a fit).
    pub stator_resistance: N,
    /// The last test's outcome.
    pub outcome: InverterTestOutcome,
}

impl<N: Num> InverterTest<N> {
    /// Arms the test for a start (the correction is kept).
    pub fn restart(&mut self, d: &InverterTestDesign<N>) {
        self.level = 0;
        self.within = 0;
        if d.level_steps > 0 {
            self.outcome = InverterTestOutcome::Running;
        }
    }

    /// Whether the test is measuring (magnetizing waits for it).
    #[inline(always)]
    pub fn running(&self) -> bool {
        self.outcome == InverterTestOutcome::Running
    }

    /// The rotor turns: the test does not apply.
    pub fn skip(&mut self) {
        if self.running() {
            self.outcome = InverterTestOutcome::Skipped;
        }
    }

    /// One magnetizing step while [`InverterTest::running`]: `current` the measured d-axis
    /// current (A), `voltage` the d-axis voltage applied over the last period less the
    /// flux model's d lambda_R/dt (V), `inv_dc_bus` 1/V_dc. Returns the d-axis current
    /// reference for the next step (A).
    pub fn update(
        &mut self,
        d: &InverterTestDesign<N>,
        current: N,
        voltage: N,
        inv_dc_bus: N,
    ) -> N {
        let (level, within) = (self.level, self.within);
        if within == d.settle_steps {
            self.mean_current = current;
            self.mean_voltage = voltage;
        } else if within > d.settle_steps {
            self.mean_current = self.mean_current + N::gain(d.filter, current - self.mean_current);
            self.mean_voltage = self.mean_voltage + N::gain(d.filter, voltage - self.mean_voltage);
        }
        self.within = within.saturating_add(1);
        if self.within >= d.level_steps {
            // the level's mean is its point; the last level's ends the test
            if let Some(p) = self.points.get_mut(level) {
                *p = (self.mean_current, self.mean_voltage);
            }
            self.level = level.saturating_add(1);
            self.within = 0;
            if self.level >= self.points.len() {
                self.fit(d, inv_dc_bus);
            }
        }
        match d.levels.get(self.level) {
            Some(&i) if self.running() => i,
            _ => d.levels[2],
        }
    }

    /// The straight line y = Rs i + (4/3) dV through the three levels (least squares with
    /// the design's weights, no division here); dV as a duty of the bus.
    fn fit(&mut self, d: &InverterTestDesign<N>, inv_dc_bus: N) {
        let followed = self
            .points
            .iter()
            .zip(d.levels.iter().zip(d.tolerances.iter()))
            .all(|(&(i, _), (&level, &tol))| (i - level).abs() <= tol);
        if !followed {
            self.outcome = InverterTestOutcome::Rejected;
            return;
        }
        let [(_, y0), (_, y1), (_, y2)] = self.points;
        let [e0, e1, e2] = d.error_weights;
        let [s0, s1, s2] = d.slope_weights;
        let error = N::gain(e0, y0) + N::gain(e1, y1) + N::gain(e2, y2);
        let slope = N::gain(s0, y0) + N::gain(s1, y1) + N::gain(s2, y2);
        let duty = self.correction_duty + error * inv_dc_bus;
        let (centre, half_width) = d.resistance_window;
        if duty.is_finite()
            && slope.is_finite()
            && duty.abs() <= d.max_duty
            && (slope - centre).abs() <= half_width
        {
            self.correction_duty = duty;
            self.stator_resistance = slope;
            self.outcome = InverterTestOutcome::Identified;
        } else {
            self.outcome = InverterTestOutcome::Rejected;
        }
    }
}

impl InverterTestDesign<f32> {
    /// This design in the arithmetic `N` with the bases `b`; fails naming the setting the
    /// value depends on.
    pub fn convert<N: Num + Units>(
        &self,
        b: &PerUnitBases,
    ) -> Result<InverterTestDesign<N>, &'static str> {
        let g = crate::num::gain_in::<N>;
        let pu =
            |x: f32, base: f32, field: &'static str| N::checked_from_f32(x / base).ok_or(field);
        let current = |x: f32| pu(x, b.current, "loops.flux_current");
        let r = b.resistance();
        Ok(InverterTestDesign {
            level_steps: self.level_steps,
            settle_steps: self.settle_steps,
            levels: [
                current(self.levels[0])?,
                current(self.levels[1])?,
                current(self.levels[2])?,
            ],
            tolerances: [
                current(self.tolerances[0])?,
                current(self.tolerances[1])?,
                current(self.tolerances[2])?,
            ],
            filter: g(self.filter, "loops.control_period")?,
            // dimensionless: voltage in, voltage out
            error_weights: [
                g(self.error_weights[0], "start.inverter_identification")?,
                g(self.error_weights[1], "start.inverter_identification")?,
                g(self.error_weights[2], "start.inverter_identification")?,
            ],
            // 1/A: V_base y w / R_base = y (w I_base) in resistance per unit
            slope_weights: [
                g(self.slope_weights[0] * b.current, "loops.flux_current")?,
                g(self.slope_weights[1] * b.current, "loops.flux_current")?,
                g(self.slope_weights[2] * b.current, "loops.flux_current")?,
            ],
            resistance_window: (
                pu(self.resistance_window.0, r, "start.inverter_identification")?,
                pu(self.resistance_window.1, r, "start.inverter_identification")?,
            ),
            max_duty: N::from_f32(self.max_duty),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(rs: f32, dv: f32, vdc: f32, noise: f32) -> InverterTest {
        let d = InverterTestDesign::new(true, 2e-4, 1.5, 10.5);
        let mut t = InverterTest::default();
        t.restart(&d);
        let mut i_ref = d.levels[0];
        let mut k = 0u32;
        while t.running() && k < 10_000 {
            // a deterministic +/- noise on the current
            let n = if k.is_multiple_of(2) { noise } else { -noise };
            let i = i_ref + n;
            let y = rs * i_ref + 4.0 / 3.0 * dv;
            i_ref = t.update(&d, i, y, 1.0 / vdc);
            k += 1;
        }
        assert_eq!(k, 3 * d.level_steps, "the test takes its three levels");
        t
    }

    #[test]
    fn the_intercept_is_the_uncompensated_error() {
        // dead time 0.7 us short at 5 kHz on 325 V: 1.14 V per leg
        let dv = 0.7e-6 / 2e-4 * 325.0;
        let t = run(10.5, dv, 325.0, 0.0);
        assert_eq!(t.outcome, InverterTestOutcome::Identified);
        assert!(
            (t.correction_duty * 325.0 - dv).abs() < 1e-3 * dv + 1e-4,
            "{t:?}"
        );
        assert!((t.stator_resistance - 10.5).abs() < 1e-3);
        // current noise does not enter (the loop holds the references)
        let t = run(10.5, -dv, 325.0, 0.01);
        assert!((t.correction_duty * 325.0 + dv).abs() < 0.02 * dv, "{t:?}");
    }

    #[test]
    fn a_flat_current_or_a_wild_fit_keeps_the_correction() {
        let d = InverterTestDesign::new(true, 2e-4, 1.5, 10.5);
        let mut t = InverterTest::<f32> {
            correction_duty: 0.001,
            ..Default::default()
        };
        t.restart(&d);
        while t.running() {
            // the current loop does not follow: the same current at every level
            t.update(&d, 0.9, 10.0, 1.0 / 325.0);
        }
        assert_eq!(t.outcome, InverterTestOutcome::Rejected);
        assert_eq!(t.correction_duty, 0.001);
        let mut t = InverterTest::<f32>::default();
        t.restart(&d);
        let mut i = d.levels[0];
        while t.running() {
            i = t.update(&d, i, 300.0, 1.0 / 325.0);
        }
        assert_eq!(
            t.outcome,
            InverterTestOutcome::Rejected,
            "an error of 0.7 V_dc"
        );
        let mut t = InverterTest::<f32>::default();
        t.restart(&d);
        let mut i = d.levels[0];
        while t.running() {
            i = t.update(&d, i, f32::NAN, 1.0 / 325.0);
        }
        assert_eq!(t.outcome, InverterTestOutcome::Rejected);
        assert_eq!(t.correction_duty, 0.0);
        // a slope outside 0.5-2.5 times the nominal Rs (here 3x, with a plausible
        // intercept) did not see the machine: rejected, so it cannot preset Rs
        let t = run(3.0 * 10.5, 0.5, 325.0, 0.0);
        assert_eq!(t.outcome, InverterTestOutcome::Rejected, "{t:?}");
        let t = run(2.4 * 10.5, 0.5, 325.0, 0.0);
        assert_eq!(t.outcome, InverterTestOutcome::Identified, "{t:?}");
    }

    #[test]
    fn off_means_never_running() {
        let d = InverterTestDesign::new(false, 2e-4, 1.5, 10.5);
        let mut t = InverterTest::<f32>::default();
        t.restart(&d);
        assert!(!t.running());
        assert_eq!(t.outcome, InverterTestOutcome::NotRun);
    }
}
