//! The start sequence while magnetizing: the flux builds at zero torque with the frame
//! held (the observer assumes a settled flux, paper section 4); meanwhile the flying
//! start's speed search decides whether the rotor turns ([`crate::speed_search`]), the
//! inverter test measures the inverter's voltage error at rest
//! ([`crate::inverter_test`]), the current channels' relative gain is calibrated
//! ([`crate::gain_calibration`]) and the stator resistance is identified at standstill
//! (eq. 19-20's residual settling). It hands over to the running cascade through one
//! value, [`StartOutput`]: the drive applies the catch, the resistance preset and the
//! handover to its estimators and speed loop.
//!
//! The phases, in order ([`StartPhase`]): with the switches still off, the wait for
//! the current channels' zero offsets (a start asked for before the idle measurement has
//! settled waits for it: the drive performs it once it has); then the speed search (at
//! the flux current it is designed for), then either the catch of a turning rotor (the frame turns with it and
//! the flux builds again in that frame) or, at rest, the inverter test's levels and the
//! Rs identification; magnetized when the flux has settled and every test is done.

use crate::frames::Dq;
use crate::gain_calibration::{GainCalibration, GainCalibrationConfig};
use crate::inverter_test::{InverterTest, InverterTestDesign, InverterTestOutcome};
use crate::num::Arithmetic;
use crate::num::PerUnitBases;
use crate::speed_search::{SearchOutcome, SpeedSearch, SpeedSearchDesign};
use crate::supervisor::{DriveState, FaultReason};

/// The magnetizing sequence's constants (flux build-up and standstill Rs identification).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MagnetizingDesign<N: Arithmetic = f32> {
    /// Whether magnetizing waits for the Rs identification.
    pub identify_rs: bool,
    /// Longest identification, steps from the start: `rs_identification_timeout`, plus the
    /// speed search and the inverter test when the test runs (the identification begins
    /// after them).
    pub rs_timeout_steps: u32,
    /// Settled-residual time, steps.
    pub rs_settle_steps: u32,
    /// Settled-residual threshold, A.
    pub rs_settled_error: N,
    /// Low-pass coefficient of the residual filter (Ts / 20 ms).
    pub residual_filter: N::Gain,
    /// The flying start's speed search.
    pub search: SpeedSearchDesign<N>,
}

/// The designs the start sequence runs with (the drive's, by reference).
#[derive(Clone, Copy, Debug)]
pub struct StartSequenceConfig<'a, N: Arithmetic> {
    /// Flux build-up, Rs identification and the speed search.
    pub magnetizing: &'a MagnetizingDesign<N>,
    /// The inverter test at rest.
    pub inverter_test: &'a InverterTestDesign<N>,
    /// The current channels' gain calibration.
    pub gain_calibration: &'a GainCalibrationConfig<N>,
    /// Rs estimation is on: the inverter test's slope presets the identification.
    pub preset_rs: bool,
    /// i_sd*, A.
    pub flux_current: N,
    /// R_R, ohm.
    pub referred_rotor_resistance: N,
    /// 1/tau_r: flux -> voltage (lambda_r / tau_r).
    pub inv_rotor_time_constant: N::Gain,
}

/// This step's signals the start sequence reads.
#[derive(Clone, Copy, Debug)]
pub struct StartInputs<N> {
    /// The voltage applied over the past period (rotor-flux frame), V.
    pub applied_voltage: Dq<N>,
    /// 1/V_dc of the bus that voltage was computed for, 1/V.
    pub inv_dc_bus: N,
    /// Measured i_dq, A.
    pub current: Dq<N>,
    /// Rs_hat, ohm.
    pub stator_resistance: N,
    /// Model rotor flux lambda_r, Wb.
    pub rotor_flux: N,
    /// The flux was settled at the start of this step.
    pub flux_settled: bool,
    /// The standstill identification's filtered d-axis residual, A.
    pub filtered_residual: N,
}

/// What the start sequence hands the cascade this step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StartOutput<N> {
    /// i_sd*, A (the inverter test's level while it runs; i_sq* is zero).
    pub i_sd_ref: N,
    /// The speed search found the rotor turning at this speed (rad/s mechanical): the
    /// observer starts from it and the flux builds again from zero in the turning frame.
    pub caught: Option<N>,
    /// The inverter test's fit gives the stator resistance at rest (ohm): the standstill
    /// identification goes on from it.
    pub rs_preset: Option<N>,
    /// Magnetized: hand over to the running cascade (the observer starts running, the
    /// speed loop starts from the speed the rotor turns at).
    pub magnetized: bool,
}

/// Where the start sequence is (telemetry and tests).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartPhase {
    /// Switches off: a start waits for the idle offset measurement to settle.
    WaitOffsets,
    /// The flying start's speed search.
    SpeedSearch,
    /// A turning rotor caught: the flux builds in the frame turning with it.
    Catch,
    /// The inverter test's levels at rest.
    InverterTest,
    /// Waiting for the flux and the standstill Rs identification to settle.
    Settling,
}

/// The start sequence's state.
#[derive(Clone, Debug, Default)]
pub struct StartSequence<N: Arithmetic> {
    /// Steps since magnetizing began.
    steps: u32,
    /// Steps the identification's residual has been settled.
    rs_settled_steps: u32,
    /// A flying start: magnetizing in a frame turning with the rotor at the speed the
    /// search measured.
    flying: bool,
    /// The flying start's speed search.
    pub search: SpeedSearch<N>,
    /// The inverter test at start and its correction (kept while running: the
    /// modulator compensates it and the running tracker adapts it).
    pub inverter: InverterTest<N>,
    /// The current sensors' relative gain, calibrated while magnetizing at rest.
    pub gain_cal: GainCalibration<N>,
    /// A start asked for before the switches-off offset measurement had settled: the
    /// state it goes to once it has.
    waiting: Option<DriveState>,
}

impl<N: Arithmetic> StartSequence<N> {
    /// Back to the start of magnetizing (the inverter test's and the calibration's
    /// results are kept: a start restarts them with their designs).
    pub fn reset(&mut self) {
        self.steps = 0;
        self.rs_settled_steps = 0;
        self.search = SpeedSearch::new();
        self.flying = false;
    }

    /// A start to `to` waits for the switches-off offsets to settle.
    pub fn wait_for_offsets(&mut self, to: DriveState) {
        self.waiting = Some(to);
    }

    /// The state a waiting start goes to, if one waits.
    pub fn waiting(&self) -> Option<DriveState> {
        self.waiting
    }

    /// No start waits any more (a stop, or the start performed).
    pub fn cancel_wait(&mut self) {
        self.waiting = None;
    }

    /// One step with the switches off: once the offsets have `settled`, the waiting start
    /// (taken: the drive performs it now).
    #[inline(always)]
    pub fn offsets_settled(&mut self, settled: bool) -> Option<DriveState> {
        if settled {
            self.waiting.take()
        } else {
            None
        }
    }

    /// A flying start is magnetizing in the frame turning with the rotor.
    #[inline(always)]
    pub fn flying(&self) -> bool {
        self.flying
    }

    /// Counts one magnetizing step and returns the steps since magnetizing began (the
    /// supervisor's magnetizing timeout judges them).
    #[inline(always)]
    pub fn count(&mut self) -> u32 {
        self.steps = self.steps.saturating_add(1);
        self.steps
    }

    /// The phase the sequence is in.
    pub fn phase(&self, cfg: &StartSequenceConfig<'_, N>) -> StartPhase {
        if self.waiting.is_some() {
            StartPhase::WaitOffsets
        } else if !self.search.done(&cfg.magnetizing.search) {
            StartPhase::SpeedSearch
        } else if self.flying {
            StartPhase::Catch
        } else if self.inverter.running() {
            StartPhase::InverterTest
        } else {
            StartPhase::Settling
        }
    }

    /// One magnetizing step (after [`Self::count`]). Fails with `OverSpeed` when the
    /// search finds the rotor beyond the speed the drive may catch.
    #[inline(always)]
    pub fn update(
        &mut self,
        cfg: &StartSequenceConfig<'_, N>,
        x: &StartInputs<N>,
    ) -> Result<StartOutput<N>, FaultReason> {
        let mag = cfg.magnetizing;
        let mut out = StartOutput {
            i_sd_ref: cfg.flux_current,
            caught: None,
            rs_preset: None,
            magnetized: false,
        };
        // flying start: the speed search on the voltage of the held frame
        match self.search.update(
            &mag.search,
            x.applied_voltage,
            x.current,
            x.stator_resistance,
        ) {
            Some(SearchOutcome::Turning(speed)) => {
                // catch the rotor: the frame turns with it from the next step (zero
                // slip at zero torque current) and the flux builds again from zero
                // in that frame (the search's flux decays with tau_r meanwhile)
                self.flying = true;
                self.gain_cal.abandon();
                out.caught = Some(speed);
            }
            Some(SearchOutcome::OverSpeed) => return Err(FaultReason::OverSpeed),
            _ => {}
        }
        self.rs_settled_steps = if x.filtered_residual.abs() < mag.rs_settled_error {
            self.rs_settled_steps.saturating_add(1)
        } else {
            0
        };
        // standstill Rs identification: wait for 50 ms of settled residual (not on
        // a flying start: the rotor does not stand still)
        let rs_done = !mag.identify_rs
            || self.flying
            || self.rs_settled_steps > mag.rs_settle_steps
            || self.steps > mag.rs_timeout_steps;
        // the inverter test holds the d-axis current at its levels
        // for 0.45 s from the search's decision: the search measures at the flux
        // current it is designed for (at the test's first level, 0.4 of it, the Q7.24
        // search read -390 rpm of -493 and the drive stalled); on a flying start the
        // test does not apply
        // the d-axis voltage the flux model predicts at rest, without the inverter's
        // error: R_s_hat i_d + R_R i_d - lambda_R / tau_r (referred)
        let rotor_voltage = cfg.referred_rotor_resistance * x.current.d
            - N::gain(cfg.inv_rotor_time_constant, x.rotor_flux);
        // the beta voltage less Rs_hat times the measured beta current the loops leave
        // (near zero): what remains is the drop of the beta current they cannot see
        if !self.flying {
            self.gain_cal.update(
                cfg.gain_calibration,
                x.applied_voltage.q - x.stator_resistance * x.current.q,
                x.stator_resistance * x.current.d + rotor_voltage,
            );
        }
        if self.inverter.running() && self.search.done(&mag.search) {
            if self.flying {
                self.inverter.skip();
            } else {
                // the d-axis voltage less the flux model's d lambda_R / dt (exact
                // in fixed point; in f32 within rounding of the two-term form)
                let voltage = x.applied_voltage.d - rotor_voltage;
                out.i_sd_ref =
                    self.inverter
                        .update(cfg.inverter_test, x.current.d, voltage, x.inv_dc_bus);
                // its fit's slope is the stator resistance at rest: with Rs estimation
                // on, the standstill identification goes on from it (with a +50 %
                // initial error it otherwise reached its timeout, which counts from
                // the start, before settling)
                if cfg.preset_rs && self.inverter.outcome == InverterTestOutcome::Identified {
                    out.rs_preset = Some(self.inverter.stator_resistance);
                }
            }
        }
        if x.flux_settled && rs_done && self.search.done(&mag.search) && !self.inverter.running() {
            self.gain_cal.finish(cfg.gain_calibration);
            self.flying = false;
            out.magnetized = true;
        }
        Ok(out)
    }
}

impl MagnetizingDesign<f32> {
    /// This design in the arithmetic `N` with the bases `b`; fails naming the setting the
    /// value depends on.
    pub fn convert<N: Arithmetic>(
        &self,
        b: &PerUnitBases,
    ) -> Result<MagnetizingDesign<N>, &'static str> {
        Ok(MagnetizingDesign {
            identify_rs: self.identify_rs,
            rs_timeout_steps: self.rs_timeout_steps,
            rs_settle_steps: self.rs_settle_steps,
            rs_settled_error: N::checked_from_f32(self.rs_settled_error / b.current)
                .ok_or("loops.flux_current")?,
            residual_filter: N::gain_from_f32(self.residual_filter)
                .ok_or("loops.control_period")?,
            search: self.search.convert(b)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::{DriveCoeffs, DriveConfig, DriveDesign};

    fn coeffs(flying: bool, inverter: bool, identify_rs: bool) -> DriveCoeffs {
        let mut cfg = DriveConfig::paper_defaults();
        cfg.start.flying_start = flying;
        cfg.start.inverter_identification = inverter;
        cfg.start.rs_standstill_identification = identify_rs;
        DriveCoeffs::new(&DriveDesign::new(cfg).unwrap(), &()).unwrap()
    }

    fn config(c: &DriveCoeffs) -> StartSequenceConfig<'_, f32> {
        StartSequenceConfig {
            magnetizing: &c.magnetizing,
            inverter_test: &c.inverter_test,
            gain_calibration: &c.gain_calibration,
            preset_rs: c.rs.adapt,
            flux_current: c.cascade.i_sd_ref,
            referred_rotor_resistance: c.model.referred_rotor_resistance,
            inv_rotor_time_constant: c.model.inv_rotor_time_constant,
        }
    }

    /// The first phase: a start asked for before the offsets settled waits with the
    /// switches off and is handed to the drive once they have, once; a stop cancels it.
    #[test]
    fn a_start_waits_for_the_offsets_then_goes_once() {
        let c = coeffs(true, true, true);
        let mut s = StartSequence::<f32>::default();
        assert_eq!(s.waiting(), None);
        s.wait_for_offsets(DriveState::Magnetizing);
        assert_eq!(s.phase(&config(&c)), StartPhase::WaitOffsets);
        assert_eq!(s.offsets_settled(false), None);
        assert_eq!(s.waiting(), Some(DriveState::Magnetizing));
        assert_eq!(s.offsets_settled(true), Some(DriveState::Magnetizing));
        assert_eq!(s.offsets_settled(true), None);
        assert_ne!(s.phase(&config(&c)), StartPhase::WaitOffsets);
        s.wait_for_offsets(DriveState::OpenLoop);
        s.cancel_wait();
        assert_eq!(s.offsets_settled(true), None);
    }

    fn at_rest(c: &DriveCoeffs, flux_settled: bool) -> StartInputs<f32> {
        StartInputs {
            applied_voltage: Dq { d: 0.0, q: 0.0 },
            inv_dc_bus: 1.0 / 325.0,
            current: Dq {
                d: c.cascade.i_sd_ref,
                q: 0.0,
            },
            stator_resistance: c.cascade.rs_initial,
            rotor_flux: 0.0,
            flux_settled,
            filtered_residual: 1.0,
        }
    }

    #[test]
    fn without_tests_it_hands_over_once_the_flux_has_settled() {
        let c = coeffs(false, false, false);
        let cfg = config(&c);
        let mut s = StartSequence::<f32>::default();
        assert_eq!(s.phase(&cfg), StartPhase::Settling);
        for k in 1..=10 {
            assert_eq!(s.count(), k);
            let out = s.update(&cfg, &at_rest(&c, false)).unwrap();
            assert!(!out.magnetized && out.caught.is_none() && out.rs_preset.is_none());
            assert_eq!(out.i_sd_ref, c.cascade.i_sd_ref);
        }
        s.count();
        assert!(s.update(&cfg, &at_rest(&c, true)).unwrap().magnetized);
        s.reset();
        assert_eq!(s.count(), 1);
    }

    #[test]
    fn the_standstill_identification_waits_for_a_settled_residual() {
        let c = coeffs(false, false, true);
        let cfg = config(&c);
        let mut s = StartSequence::<f32>::default();
        // an unsettled residual holds the hand-over (until the timeout)
        for _ in 0..c.magnetizing.rs_settle_steps + 5 {
            s.count();
            assert!(!s.update(&cfg, &at_rest(&c, true)).unwrap().magnetized);
        }
        let settled = StartInputs {
            filtered_residual: 0.0,
            ..at_rest(&c, true)
        };
        let mut steps = 0;
        loop {
            s.count();
            steps += 1;
            if s.update(&cfg, &settled).unwrap().magnetized {
                break;
            }
            assert!(steps <= c.magnetizing.rs_settle_steps + 1);
        }
        assert_eq!(steps, c.magnetizing.rs_settle_steps + 1);
    }

    #[test]
    fn the_search_comes_first_and_the_inverter_test_sets_the_flux_current() {
        let c = coeffs(true, true, false);
        let cfg = config(&c);
        let mut s = StartSequence::<f32>::default();
        s.inverter.restart(&c.inverter_test);
        assert_eq!(s.phase(&cfg), StartPhase::SpeedSearch);
        let mut levels = false;
        let mut handed = false;
        for _ in 0..20_000 {
            s.count();
            let out = s.update(&cfg, &at_rest(&c, true)).unwrap();
            if s.phase(&cfg) == StartPhase::InverterTest {
                levels |= out.i_sd_ref < c.cascade.i_sd_ref;
            }
            if out.magnetized {
                handed = true;
                break;
            }
        }
        assert!(levels, "the inverter test held a lower level");
        assert!(handed, "magnetized once the search and the test are done");
        assert_eq!(s.phase(&cfg), StartPhase::Settling);
    }
}
