//! The fixed-point drive: the one cascade of [`crate::drive`] instantiated with
//! [`Q24`] (Q7.24 per unit) and the table sin/cos, plus what only this arithmetic needs:
//! the modulator's voltage limit in Q7.24, duties as Q15 timer codes, and the SI boundary
//! the simulator uses ([`FixedDrive::step_si`]: a NaN/inf sample, impossible in integers,
//! is reported as `NonFiniteInput` like the f32 drive; a saturated ADC code is an
//! over-current).
//!
//! Configuration: [`FixedDrive::with_bases`] takes the same [`DriveConfig`] as the f32 drive and
//! builds the same [`DriveDesign`] (validated once, every derived constant computed
//! once); [`crate::design::DriveCoeffs::new`] rescales it with the per-unit bases, each
//! block its own design, checking that the configured ranges fit them.

use super::q::{clamp, to_q24, ONE, Q24};
use super::trig::TableSinCos;
use super::PerUnitBases;
use crate::design::{ConfigError, CurrentSensing, DriveConfig, DriveDesign};
use crate::drive::{Drive, DriveInputs, DriveTelemetry, PwmOutput};
use crate::frames::SinCos;
use crate::frames::{AlphaBeta, Dq};
use crate::math::is_finite;
use crate::num::Angles;
use crate::num::Num;
use crate::observer::{ReducedOrderObserver, SpeedObserver};
use crate::supervisor::{CommandError, DriveState, FaultReason};
use crate::svpwm::{modulate_signed, Modulation, Modulator, Svpwm, SvpwmConfig, VoltageLimit};

/// The fixed-point sensorless IFOC drive (the paper's observer, SVPWM, table sin/cos).
pub type FixedDrive = Drive<TableSinCos, Q24, ReducedOrderObserver<Q24>, Svpwm>;
/// Samples of one fixed-point step, Q7.24 pu.
pub type FixedInputs = DriveInputs<Q24>;
/// The PWM command of one fixed-point step (duties Q7.24; [`PwmOutput::q15`] for the
/// timer).
pub type FixedPwm = PwmOutput<Q24>;
/// Telemetry of one fixed-point step, Q7.24 pu.
pub type FixedTelemetry = DriveTelemetry<Q24>;

/// 0.98/sqrt(3): the voltage circle inside the hexagon, as a fraction of V_dc (Q7.24).
const V_MAX_PER_BUS: Q24 = Q24(9_492_603);

impl Modulator<Q24> for Svpwm {
    /// 98 % of the inscribed circle V_dc/sqrt(3), as the f32 modulator.
    #[inline(always)]
    fn voltage_limit(
        &self,
        pwm: &SvpwmConfig<Q24>,
        dc_bus: Q24,
        inv_dc_bus: Q24,
    ) -> VoltageLimit<Q24> {
        let max = dc_bus * V_MAX_PER_BUS;
        let inv_max = Q24::gain(pwm.voltage_limit_per_inv_bus, inv_dc_bus);
        VoltageLimit {
            max,
            inv_max,
            steady: max,
            sustained: max,
            inv_sustained: inv_max,
        }
    }
    #[inline(always)]
    fn modulate(
        &self,
        pwm: &SvpwmConfig<Q24>,
        v: AlphaBeta<Q24>,
        dc_bus: Q24,
        inv_dc_bus: Q24,
        current_signs: [Q24; 3],
        dead_time_correction: Q24,
    ) -> Modulation<Q24> {
        modulate_signed(
            pwm,
            v,
            dc_bus,
            inv_dc_bus,
            current_signs,
            dead_time_correction,
        )
    }
}

impl PwmOutput<Q24> {
    /// The duties as Q15 timer codes (32768 = always on; 16384 when disabled), rounded.
    pub fn q15(&self) -> [u16; 3] {
        self.duties
            .map(|d| (clamp(d.0, 0, ONE).saturating_add(1 << 8) >> 9) as u16)
    }
}

impl FixedDrive {
    /// Validates `cfg` (as the f32 drive does, plus the fit to `bases`) and converts its
    /// design; an idle drive.
    pub fn with_bases(cfg: DriveConfig, bases: PerUnitBases) -> Result<Self, ConfigError> {
        Self::from_design(DriveDesign::new(cfg)?, bases)
    }

    /// Converts the f32 design with `bases`; an idle drive.
    pub fn from_design(design: DriveDesign, bases: PerUnitBases) -> Result<Self, ConfigError> {
        if design.config.estimation.observer != crate::config::ObserverChoice::Reduced {
            return Err(ConfigError::Invalid {
                field: "estimation.observer",
                rule: "the paper's observer (\"reduced\"): the flux observer runs in f32 only",
            });
        }
        Self::with_parts(
            design,
            bases,
            TableSinCos,
            ReducedOrderObserver::new(),
            Svpwm,
        )
    }
}

/// The simulator boundary (f32 SI <-> per unit) of any fixed-point drive; not for the
/// control interrupt.
impl<S: SinCos<Q24>, O: SpeedObserver<Q24>, M: Modulator<Q24>> Drive<S, Q24, O, M> {
    /// Sets the speed target in rad/s mechanical (boundary conversion).
    pub fn set_speed_target_si(&mut self, speed: f32) -> Result<(), CommandError> {
        if !is_finite(speed) {
            return Err(CommandError::NotFinite);
        }
        let limit = self.design().cascade.speed_target_limit;
        let s = crate::math::clamp(speed, -limit, limit);
        self.set_speed_target(Q24(to_q24(s / self.bases().speed)))
    }

    /// Converts SI samples to per unit, runs [`Drive::step`] and converts the duties back
    /// (through the Q15 timer codes, as the hardware would see them). A non-finite sample
    /// (only possible at this boundary) faults the drive with `NonFiniteInput`.
    pub fn step_si(&mut self, inp: &DriveInputs) -> PwmOutput {
        let [a, b, c] = inp.phase_currents;
        // with two shunts the third sample is not a measurement: ignored, as the f32
        // drive ignores it (it derives c = -a - b)
        let c = match self.config().inverter.current_sensing {
            CurrentSensing::TwoPhase => 0.0,
            CurrentSensing::ThreePhase => c,
        };
        let finite = is_finite(a) && is_finite(b) && is_finite(c) && is_finite(inp.dc_bus);
        if !finite {
            if self.state() != DriveState::Fault {
                self.trip(FaultReason::NonFiniteInput);
            }
            return PwmOutput::OFF;
        }
        let bases = *self.bases();
        let ib = 1.0 / bases.current;
        let out = self.step(&FixedInputs {
            phase_currents: [
                Q24(to_q24(a * ib)),
                Q24(to_q24(b * ib)),
                Q24(to_q24(c * ib)),
            ],
            dc_bus: Q24(to_q24(inp.dc_bus / bases.voltage)),
        });
        if !out.enabled {
            return PwmOutput::OFF;
        }
        let k = 1.0 / 32768.0;
        PwmOutput {
            duties: out.q15().map(|d| d as f32 * k),
            enabled: true,
        }
    }

    /// The last step's telemetry in SI units (boundary conversion).
    pub fn telemetry_si(&self) -> DriveTelemetry {
        let t = self.telemetry();
        let b = self.bases();
        let dq = |v: Dq<Q24>, base: f32| Dq {
            d: v.d.to_pu() * base,
            q: v.q.to_pu() * base,
        };
        DriveTelemetry {
            speed_reference: t.speed_reference.to_pu() * b.speed,
            speed_estimate: t.speed_estimate.to_pu() * b.speed,
            load_torque_estimate: t.load_torque_estimate.to_pu() * b.torque,
            torque_estimate: t.torque_estimate.to_pu() * b.torque,
            current: dq(t.current, b.current),
            current_reference: dq(t.current_reference, b.current),
            voltage: dq(t.voltage, b.voltage),
            rotor_flux: t.rotor_flux.to_pu() * b.flux,
            stator_resistance_estimate: t.stator_resistance_estimate.to_pu() * b.resistance(),
            angle: Q24::angle_to_rad(t.angle),
            stator_frequency: t.stator_frequency.to_pu() * b.frequency,
            voltage_saturated: t.voltage_saturated,
            speed_target_limited: t.speed_target_limited,
            current_error: t.current_error.to_pu() * b.current,
            model_residual: t.model_residual.to_pu() * b.voltage,
            search_speed: t.search_speed.to_pu() * b.speed,
            zero_speed_held: t.zero_speed_held,
        }
    }

    /// The q-current limit sqrt(I_max^2 - i_sd*^2), A (as the f32 drive reports it).
    pub fn torque_current_limit_si(&self) -> f32 {
        self.torque_current_limit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::design::STALL_SPEED_FRACTION;

    use crate::svpwm::{INV_SQRT3, VOLTAGE_MARGIN};
    use proptest::prelude::*;

    /// The Q7.24 literals are the design's named fractions.
    #[test]
    fn literals_are_the_design_constants() {
        // the two irrational literals were computed from the exact values (0.98/sqrt 3 is
        // 9 492 603.5 codes, sqrt 3 is 29 058 990.9); the f32 constants land one code away
        assert_eq!(V_MAX_PER_BUS.0 + 1, to_q24(VOLTAGE_MARGIN * INV_SQRT3));
        assert_eq!(
            <Q24 as crate::num::ThreePhase>::SQRT3.0 - 1,
            to_q24(1.732_050_8)
        );
        let d = DriveDesign::new(DriveConfig::paper_defaults()).unwrap();
        let c = crate::design::DriveCoeffs::<Q24>::new(&d, &PerUnitBases::PAPER).unwrap();
        assert_eq!(c.limits.stall_fraction.0, to_q24(STALL_SPEED_FRACTION));
        assert_eq!(c.limits.stall_fraction.0, 1_677_722);
    }

    /// The fixed drive is built from the same design as the f32 drive: a setting the
    /// design rejects is rejected with the same error; one that does not fit the bases
    /// names its field.
    #[test]
    fn rejects_what_the_design_rejects() {
        let mut c = DriveConfig::paper_defaults();
        c.loops.speed_bandwidth = 900.0;
        assert_eq!(
            FixedDrive::with_bases(c, PerUnitBases::PAPER).err(),
            Some(DriveDesign::new(c).unwrap_err())
        );
        let mut c = DriveConfig::paper_defaults();
        c.limits.dc_bus_max = 900.0;
        assert_eq!(
            FixedDrive::with_bases(c, PerUnitBases::PAPER)
                .err()
                .map(|e| e.field()),
            Some("limits.dc_bus_max")
        );
    }

    /// Powered long enough (switches off, no current) for the offset measurement to have
    /// settled: a start switches at the next step, so the properties reach the running
    /// step.
    fn drive() -> FixedDrive {
        let mut d =
            FixedDrive::with_bases(DriveConfig::paper_defaults(), PerUnitBases::PAPER).unwrap();
        for _ in 0..d.coeffs().limits.offset_settle_steps {
            d.step_si(&DriveInputs {
                phase_currents: [0.0; 3],
                dc_bus: 325.0,
            });
        }
        d
    }

    /// The offsets measured with the switches off are subtracted alike in both
    /// arithmetics: after the same idle samples (a 30 mA / -20 mA offset with +/-5 mA of
    /// ripple) and a start, the sensed currents of the first magnetizing step agree.
    #[test]
    fn idle_offsets_are_compensated_alike_in_both_arithmetics() {
        let cfg = DriveConfig::paper_defaults();
        let mut f = crate::Drive::new(cfg).unwrap();
        let mut q = FixedDrive::with_bases(cfg, PerUnitBases::PAPER).unwrap();
        f.start().unwrap();
        q.start().unwrap();
        for k in 0..f.coeffs().limits.offset_settle_steps {
            let ripple = if k % 2 == 0 { 0.005 } else { -0.005 };
            let inp = DriveInputs {
                phase_currents: [0.03 + ripple, -0.02 - ripple, -0.01],
                dc_bus: 325.0,
            };
            f.step(&inp);
            q.step_si(&inp);
        }
        assert_eq!(f.state(), DriveState::Magnetizing);
        assert_eq!(q.state(), DriveState::Magnetizing);
        let inp = DriveInputs {
            phase_currents: [0.53, -0.27, -0.26],
            dc_bus: 325.0,
        };
        f.step(&inp);
        q.step_si(&inp);
        let (a, b) = (f.telemetry().current, q.telemetry_si().current);
        assert!(
            (a.d - b.d).abs() < 1e-4 && (a.q - b.q).abs() < 1e-4,
            "{a:?} vs {b:?}"
        );
    }

    /// Both arithmetics treat a non-finite sample alike: with two shunts the third sample
    /// is ignored (it faulted the fixed drive but not the f32 drive); with three it faults
    /// both.
    #[test]
    fn non_finite_samples_are_judged_alike_in_both_arithmetics() {
        for sensing in [CurrentSensing::TwoPhase, CurrentSensing::ThreePhase] {
            let mut cfg = DriveConfig::paper_defaults();
            cfg.inverter.current_sensing = sensing;
            let mut f = crate::Drive::new(cfg).unwrap();
            let mut q = FixedDrive::with_bases(cfg, PerUnitBases::PAPER).unwrap();
            f.start().unwrap();
            q.start().unwrap();
            let inp = DriveInputs {
                phase_currents: [0.1, -0.05, f32::NAN],
                dc_bus: 325.0,
            };
            let (of, oq) = (f.step(&inp), q.step_si(&inp));
            assert_eq!(of.enabled, oq.enabled, "{sensing:?}");
            assert_eq!(f.state(), q.state(), "{sensing:?}");
            assert_eq!(f.fault(), q.fault(), "{sensing:?}");
            assert_eq!(
                f.state() == DriveState::Fault,
                sensing == CurrentSensing::ThreePhase
            );
        }
    }

    /// Any Q7.24 current code, with the extremes (a saturated ADC maps to them) often.
    fn any_code() -> impl Strategy<Value = i32> {
        prop_oneof![
            4 => -to_q24(1.0)..to_q24(1.0),
            1 => Just(i32::MAX),
            1 => Just(i32::MIN),
            1 => any::<i32>(),
        ]
    }

    fn any_bus_code() -> impl Strategy<Value = i32> {
        prop_oneof![
            4 => to_q24(0.45)..to_q24(1.05),
            1 => any::<i32>(),
        ]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        /// The fixed-point twin of the f32 drive's `never_emits_bad_duty`: whatever the
        /// samples, the duties are in 0 ..= 1.0, a disabled output is the neutral 0.5
        /// (16384 in Q15), a fault keeps the switches off, and an over-range current faults.
        #[test]
        fn never_emits_bad_duty(
            samples in proptest::collection::vec((any_code(), any_code(), any_code(), any_bus_code()), 1..400),
            target in -to_q24(0.2)..to_q24(0.2),
            vf in any::<bool>(),
        ) {
            let mut d = drive();
            d.set_speed_target(Q24(target)).unwrap();
            if vf { d.start_open_loop().unwrap(); } else { d.start().unwrap(); }
            let trip = to_q24(DriveConfig::paper_defaults().limits.overcurrent_trip / PerUnitBases::PAPER.current);
            for (a, b, c, bus) in samples {
                let was = d.state();
                let out = d.step(&FixedInputs { phase_currents: [Q24(a), Q24(b), Q24(c)], dc_bus: Q24(bus) });
                prop_assert!(out.duties.iter().all(|x| (0..=ONE).contains(&x.0)));
                prop_assert!(out.q15().iter().all(|&x| x <= 32768));
                if !out.enabled { prop_assert_eq!(out.q15(), [16384; 3]); }
                if d.state() == DriveState::Fault { prop_assert!(!out.enabled); }
                let over = a.saturating_abs() > trip || b.saturating_abs() > trip
                    || a.saturating_add(b).saturating_abs() > trip;
                if over && was != DriveState::Fault {
                    prop_assert_eq!(d.fault(), Some(FaultReason::OverCurrent));
                }
            }
        }
    }
}
