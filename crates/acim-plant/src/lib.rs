//! # acim-plant: the induction-motor plant the drive is tested against
//!
//! What the simulator, the closed-loop tests, the cycle bench and the firmware's
//! hardware-free self-test all run the `acim` drive against: the machine (paper eq. 1-3
//! in the stationary frame), load torque, inverter (averaged or switching-level), the one
//! PWM timing model ([`PwmPreload`]: duties computed at step k act over the next period),
//! sensors, the DC link ([`DcLink`]), fault injection ([`FaultInjector`]) and the
//! inverter's hardware over-current comparator ([`ComparatorConfig`], not fitted unless
//! asked: [`Plant::set_comparator`]).
//!
//! Everything is `no_std`, allocation-free, f32-only and panic-free; no trigonometry is
//! needed at run time because the machine is integrated in the stationary alpha-beta frame.
//! Frames and transforms are the control library's ([`acim::frames`]), so the plant and
//! the controller cannot disagree on a convention.
//!
//! Conventions (those of `acim`): SI units; amplitude-invariant Clarke
//! (`i_alpha = i_a`, `i_beta = (i_a + 2 i_b)/sqrt3`), so alpha-beta values are peak phase
//! values; speeds in rad/s mechanical, electrical speed `p Omega`; torque
//! `Te = 1.5 p (Lm/Lr)(psi_alpha i_beta - psi_beta i_alpha)`.
//!
//! Typical use, once per control period (default 200 us, integrated as
//! [`DEFAULT_SUBSTEPS`] = 10 RK4 steps of 20 us):
//!
//! ```
//! use acim::PwmOutput;
//! use acim_plant::{LoadTorque, Plant, PwmPreload};
//! let mut plant = Plant::paper_default(1);
//! let mut pwm = PwmPreload::new();
//! for _ in 0..100 {
//!     let m = plant.sample(); // ADC values at the period boundary (PWM centre)
//!     let _ = m;
//!     // ... the controller computes its command from m ...
//!     let command = PwmOutput { duties: [0.5; 3], enabled: true };
//!     plant.run_pwm_period(pwm.advance(command), LoadTorque::None);
//! }
//! assert!(plant.machine().speed().abs() < 1e-3);
//! ```

#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

mod comparator;
mod dc_link;
mod faults;
mod inverter;
mod load;
mod machine;
mod pwm;
mod sensors;

pub use comparator::{ComparatorConfig, ComparatorTrip};
pub use dc_link::DcLink;
pub use faults::{FaultInjector, FaultPlan};
pub use pwm::PwmPreload;

pub use inverter::{
    sanitize_duty, smooth_sign, Inverter, InverterConfig, InverterOutput, LegState, SwitchInterval,
    SwitchingPattern, DEFAULT_CURRENT_BAND, DEFAULT_DEAD_TIME, DEFAULT_DEVICE_DROP,
    DEFAULT_PWM_PERIOD,
};
pub use load::{LoadTorque, PASSIVE_SPEED_BAND};
pub use machine::{EnergyAccount, InductionMachine, MachineState, Saturation, DEFAULT_SUBSTEPS};
pub use sensors::{
    Adc, BusSensorConfig, BusVoltageSensor, CurrentChannels, CurrentSensorConfig, CurrentSensors,
    Measurements, Rng, DEFAULT_BUS_FULL_SCALE, DEFAULT_CURRENT_FULL_SCALE,
};

use acim::frames::{inverse_clarke, park, AlphaBeta, Dq, SinCosValue};
use acim::params::MachineParams;
use acim::PwmOutput;
use comparator::Comparator;
use machine::{StageSource, StepSourceIntegral};

fn max3(a: f32, b: f32, c: f32) -> f32 {
    let m = if a > b { a } else { b };
    if m > c {
        m
    } else {
        c
    }
}

fn min3(a: f32, b: f32, c: f32) -> f32 {
    let m = if a < b { a } else { b };
    if m < c {
        m
    } else {
        c
    }
}

/// How [`Plant::run_period`] models the inverter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PwmMode {
    /// Period-averaged voltages (duty * Vdc with dead-time and drop errors), integrated as
    /// `substeps` equal RK4 steps; no current ripple.
    #[default]
    Averaged,
    /// Switching level: the period is split at every switching edge of the centre-aligned
    /// pattern and the machine is integrated over each interval with its switch states
    /// (RK4 steps no longer than period/substeps); shows the current ripple.
    Switched,
}

/// Averages over the last period of [`Plant::run_period`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct PeriodReport {
    /// Mean applied v_alpha, V.
    pub v_alpha: f32,
    /// Mean applied v_beta, V.
    pub v_beta: f32,
    /// Mean DC-link current, A.
    pub dc_current: f32,
    /// Mean power drawn from the DC link, W.
    pub dc_power: f32,
    /// Mean power into the machine terminals, 1.5 (v_alpha i_alpha + v_beta i_beta), W.
    pub input_power: f32,
    /// Largest true |i_x| while the gates were on, checked at the period's start and at
    /// every integration sub-step's end (0 with the gates off all period), A.
    pub switching_peak_a: f32,
    /// Time with the gates on and the largest true |i_x| above the watch level
    /// ([`Plant::set_watch_level`]), interpolated linearly within each sub-step, s.
    pub switching_above_watch_s: f32,
}

/// Peak and time above the watch level, gates on, over one period.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Watch {
    peak: f32,
    above_s: f32,
}

impl Watch {
    /// A sub-step of `h` s over which max |i_x| went from `a` to `b`.
    fn add(&mut self, a: f32, b: f32, level: f32, h: f32) {
        if b > self.peak {
            self.peak = b;
        }
        self.above_s += comparator::time_above(a, b, level, h);
    }
}

/// Machine + inverter + sensors + load: what a simulator or the firmware's hardware-free
/// self-test steps once per control period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plant {
    machine: InductionMachine,
    inverter: Inverter,
    current_sensors: CurrentSensors,
    bus_sensor: BusVoltageSensor,
    mode: PwmMode,
    substeps: u32,
    load: LoadTorque,
    report: PeriodReport,
    periods: u64,
    /// An open motor phase (0..=2), if any.
    open_phase: Option<usize>,
    /// The hardware over-current comparator (not fitted by default) and its latch.
    comparator: Comparator,
    /// Level of [`PeriodReport::switching_above_watch_s`], A.
    watch_level: f32,
}

impl Plant {
    /// A plant from its parts, averaged PWM, [`DEFAULT_SUBSTEPS`] sub-steps per period.
    pub fn new(
        machine: InductionMachine,
        inverter: Inverter,
        current_sensors: CurrentSensors,
        bus_sensor: BusVoltageSensor,
    ) -> Self {
        let mut p = Self {
            machine,
            inverter,
            current_sensors,
            bus_sensor,
            mode: PwmMode::Averaged,
            substeps: DEFAULT_SUBSTEPS,
            load: LoadTorque::None,
            report: PeriodReport::default(),
            periods: 0,
            open_phase: None,
            comparator: Comparator::default(),
            watch_level: f32::INFINITY,
        };
        p.update_freewheel_slope();
        p
    }

    /// Table 1 machine, default inverter (1.5 us dead time, 1 V drop, 200 us) on a
    /// 325 V bus, 12-bit two-channel current sensors and a 12-bit bus sensor, without
    /// noise, gain or offset errors (set them through the sensor accessors).
    pub fn paper_default(seed: u64) -> Self {
        Self::new(
            InductionMachine::new(MachineParams::paper_table1()),
            Inverter::default(),
            CurrentSensors::g474(CurrentChannels::Two, seed),
            BusVoltageSensor::new(BusSensorConfig::default(), seed.wrapping_add(0x5eed)),
        )
    }

    /// Ideal plant for tests: ideal inverter on `dc_bus` V, ideal sensors.
    pub fn ideal(params: MachineParams, dc_bus: f32) -> Self {
        Self::new(
            InductionMachine::new(params),
            Inverter::ideal(dc_bus),
            CurrentSensors::ideal(),
            BusVoltageSensor::ideal(),
        )
    }

    fn update_freewheel_slope(&mut self) {
        let h = self.inverter.pwm_period() / self.substeps as f32;
        let l = self.machine.params().transient_inductance();
        self.inverter.set_freewheel_slope(2.0 * h / l);
    }

    /// Selects averaged or switching-level PWM.
    pub fn set_mode(&mut self, mode: PwmMode) {
        self.mode = mode;
    }

    /// The PWM model in use.
    pub fn mode(&self) -> PwmMode {
        self.mode
    }

    /// Sets the number of RK4 sub-steps per period (at least 1; default 10).
    pub fn set_substeps(&mut self, n: u32) {
        self.substeps = n.max(1);
        self.update_freewheel_slope();
    }

    /// RK4 sub-steps per period.
    pub fn substeps(&self) -> u32 {
        self.substeps
    }

    /// Control (= PWM) period, s.
    pub fn period(&self) -> f32 {
        self.inverter.pwm_period()
    }

    /// Sets the DC-bus voltage, V (a bus sag can be applied between periods).
    pub fn set_dc_bus(&mut self, v: f32) {
        self.inverter.set_dc_bus(v);
    }

    /// Runs one PWM period with duties `duties` (each clamped to [0, 1], NaN = 0.5),
    /// gates `enabled` (false: all switches off) and load `load` held over the period.
    ///
    /// With a comparator fitted ([`Plant::set_comparator`]) the gates go off within the
    /// period when a phase current crosses its level (see [`ComparatorConfig`]), and stay
    /// off, whatever `enabled` says, until [`Plant::reset_comparator`].
    pub fn run_period(&mut self, duties: [f32; 3], enabled: bool, load: LoadTorque) {
        self.update_freewheel_slope();
        self.load = load;
        let inv = self.inverter;
        let vdc = inv.dc_bus();
        let t = inv.pwm_period();
        let h_max = t / self.substeps as f32;
        let mut acc = StepSourceIntegral::default();
        let gates = enabled && self.comparator.trip.is_none();
        let mut watch = Watch {
            peak: if gates {
                comparator::max_abs(self.machine.phase_currents())
            } else {
                0.0
            },
            above_s: 0.0,
        };
        // period-averaged terminal voltages with the gates on
        let averaged = move |ia: f32, ib: f32| {
            let i = AlphaBeta {
                alpha: ia,
                beta: ib,
            };
            let out = inv.averaged_output(duties, true, inverse_clarke(i));
            StageSource {
                v_alpha: out.alpha_beta.alpha,
                v_beta: out.alpha_beta.beta,
                p_dc: vdc * out.dc_current,
            }
        };
        // when the comparator opened the gates, s from the period start
        let mut opened_at: Option<f32> = None;
        if gates && self.mode == PwmMode::Switched {
            let pattern = inv.switching_pattern(duties);
            let band = inv.config().current_band;
            let mut elapsed = 0.0f32;
            'intervals: for iv in pattern.intervals() {
                let len = iv.t1 - iv.t0;
                let ratio = len / h_max;
                let mut n = ratio as u32;
                if (n as f32) < ratio || n == 0 {
                    n += 1;
                }
                let h = len / n as f32;
                let legs = iv.legs;
                let src = move |ia: f32, ib: f32| {
                    let i = AlphaBeta {
                        alpha: ia,
                        beta: ib,
                    };
                    let out = inv.output(legs, inverse_clarke(i), band);
                    StageSource {
                        v_alpha: out.alpha_beta.alpha,
                        v_beta: out.alpha_beta.beta,
                        p_dc: vdc * out.dc_current,
                    }
                };
                for _ in 0..n {
                    opened_at =
                        self.gates_on_substep(h, load, &src, (elapsed, t), &mut acc, &mut watch);
                    if opened_at.is_some() {
                        break 'intervals;
                    }
                    elapsed += h;
                }
            }
        } else if gates {
            let mut elapsed = 0.0f32;
            for _ in 0..self.substeps {
                opened_at = self.gates_on_substep(
                    h_max,
                    load,
                    &averaged,
                    (elapsed, t),
                    &mut acc,
                    &mut watch,
                );
                if opened_at.is_some() {
                    break;
                }
                elapsed += h_max;
            }
        }
        if !gates {
            self.run_gates_off(self.substeps, h_max, load, &mut acc);
        } else if let Some(t_off) = opened_at {
            // the rest of the period with the gates off
            let rest = t - t_off;
            if rest > 0.0 {
                let ratio = rest / h_max;
                let mut n = ratio as u32;
                if (n as f32) < ratio || n == 0 {
                    n += 1;
                }
                self.run_gates_off(n, rest / n as f32, load, &mut acc);
            }
        }
        let inv_t = 1.0 / t;
        self.report = PeriodReport {
            v_alpha: acc.v_alpha_dt * inv_t,
            v_beta: acc.v_beta_dt * inv_t,
            dc_current: if vdc > 0.0 {
                acc.e_dc * inv_t / vdc
            } else {
                0.0
            },
            dc_power: acc.e_dc * inv_t,
            input_power: acc.e_in * inv_t,
            switching_peak_a: watch.peak,
            switching_above_watch_s: watch.above_s,
        };
        self.periods = self.periods.wrapping_add(1);
    }

    /// One sub-step of `h` s with the gates on (terminal source `src`), starting `elapsed`
    /// s into the period of `period` s, with the comparator's check at its end. Returns when the
    /// comparator opened the gates (s from the period start), having integrated the
    /// machine up to that instant only.
    fn gates_on_substep<F>(
        &mut self,
        h: f32,
        load: LoadTorque,
        src: &F,
        (elapsed, period): (f32, f32),
        acc: &mut StepSourceIntegral,
        watch: &mut Watch,
    ) -> Option<f32>
    where
        F: Fn(f32, f32) -> StageSource,
    {
        let before = self.machine;
        let a = comparator::max_abs(before.phase_currents());
        let step = self.machine.step_with(h, load, src);
        self.constrain_open_phase();
        let b = comparator::max_abs(self.machine.phase_currents());
        let cfg = match self.comparator.cfg {
            Some(c) if b > c.level => c,
            _ => {
                acc.add(step);
                watch.add(a, b, self.watch_level, h);
                return None;
            }
        };
        let crossing = comparator::crossing_fraction(a, b, cfg.level) * h;
        let off = crossing + cfg.delay;
        let (off, current) = if off < h {
            // again from the sub-step's start, up to the switch-off
            self.machine = before;
            if off > 0.0 {
                acc.add(self.machine.step_with(off, load, src));
                self.constrain_open_phase();
            }
            let b1 = comparator::max_abs(self.machine.phase_currents());
            watch.add(a, b1, self.watch_level, off);
            (off, b1)
        } else {
            // the switch-off falls after this sub-step: on with the same source up to it
            // (at the latest the period's end, after which the latch keeps the gates off)
            acc.add(step);
            watch.add(a, b, self.watch_level, h);
            let off = if elapsed + off > period {
                period - elapsed
            } else {
                off
            };
            let extra = off - h;
            let mut b1 = b;
            if extra > 0.0 {
                acc.add(self.machine.step_with(extra, load, src));
                self.constrain_open_phase();
                b1 = comparator::max_abs(self.machine.phase_currents());
                watch.add(b, b1, self.watch_level, extra);
            }
            (if extra > 0.0 { off } else { h }, b1)
        };
        self.comparator.trip = Some(ComparatorTrip {
            period: self.periods,
            crossing_s: elapsed + crossing,
            off_s: elapsed + off,
            current_a: current,
        });
        Some(elapsed + off)
    }

    /// `n` sub-steps of `h` s with every gate off: the diodes clamp the terminals, or the
    /// stator is open once the currents are gone (see the inverter module).
    fn run_gates_off(&mut self, n: u32, h: f32, load: LoadTorque, acc: &mut StepSourceIntegral) {
        let inv = self.inverter;
        let vdc = inv.dc_bus();
        let off = move |ia: f32, ib: f32| {
            let i = AlphaBeta {
                alpha: ia,
                beta: ib,
            };
            let out = inv.averaged_output([0.5; 3], false, inverse_clarke(i));
            StageSource {
                v_alpha: out.alpha_beta.alpha,
                v_beta: out.alpha_beta.beta,
                p_dc: vdc * out.dc_current,
            }
        };
        let band = inv.freewheel_band();
        let limit = vdc + 2.0 * inv.config().device_drop;
        for _ in 0..n {
            let small = self
                .machine
                .phase_currents()
                .iter()
                .all(|i| i.abs() <= band);
            let [e1, e2, e3] = inverse_clarke(self.machine.open_circuit_voltage());
            let spread = max3(e1, e2, e3) - min3(e1, e2, e3);
            if small && spread <= limit {
                // every diode blocked: open stator, the terminals show the back-EMF
                self.machine.step_open_circuit(load, h);
                let e = self.machine.open_circuit_voltage();
                acc.add(StepSourceIntegral {
                    v_alpha_dt: e.alpha * h,
                    v_beta_dt: e.beta * h,
                    e_dc: 0.0,
                    e_in: 0.0,
                });
            } else {
                acc.add(self.machine.step_with(h, load, &off));
                self.constrain_open_phase();
            }
        }
    }

    /// Fits (or with `None` removes) the hardware over-current comparator; a latched trip
    /// is kept.
    pub fn set_comparator(&mut self, cfg: Option<ComparatorConfig>) {
        self.comparator.cfg = cfg;
    }

    /// The comparator's configuration, if fitted.
    pub fn comparator(&self) -> Option<ComparatorConfig> {
        self.comparator.cfg
    }

    /// The comparator's latched trip, if it fired: the gates stay off until
    /// [`Plant::reset_comparator`].
    pub fn comparator_trip(&self) -> Option<ComparatorTrip> {
        self.comparator.trip
    }

    /// Releases the comparator's latch (what the drive's fault reset does to the timer's
    /// break: MOE may be set again).
    pub fn reset_comparator(&mut self) {
        self.comparator.trip = None;
    }

    /// Sets the level (A) above which [`PeriodReport::switching_above_watch_s`] counts the
    /// time with the gates on (e.g. the drive's software trip, to measure how long the
    /// true current stays above it while switching); infinite by default (nothing
    /// counted).
    pub fn set_watch_level(&mut self, level: f32) {
        self.watch_level = level;
    }

    /// Runs one PWM period with the command the inverter applies over it (the output of
    /// [`PwmPreload::advance`]), load `load` held over the period.
    pub fn run_pwm_period(&mut self, applied: PwmOutput, load: LoadTorque) {
        self.run_period(applied.duties, applied.enabled, load);
    }

    /// Opens motor phase `phase` (0..=2; `None` reconnects it): from then on that phase
    /// carries no current. Modelled by removing the stator-current component along the
    /// phase's axis after every integration step (the terminal floats to whatever voltage
    /// keeps its current at zero; the small inductive energy of that component is lost,
    /// as in the arc of a real opening).
    pub fn set_open_phase(&mut self, phase: Option<usize>) {
        self.open_phase = phase.map(|p| p.min(2));
    }

    /// The open phase, if any.
    pub fn open_phase(&self) -> Option<usize> {
        self.open_phase
    }

    fn constrain_open_phase(&mut self) {
        if let Some(k) = self.open_phase {
            // unit vector of phase k in the amplitude-invariant alpha-beta plane: the
            // phase current is its projection (inverse Clarke)
            let (ua, ub) = match k {
                0 => (1.0, 0.0),
                1 => (-0.5, 0.866_025_4),
                _ => (-0.5, -0.866_025_4),
            };
            let mut st = self.machine.state();
            let along = ua * st.i_alpha + ub * st.i_beta;
            st.i_alpha -= along * ua;
            st.i_beta -= along * ub;
            self.machine.set_state(st);
        }
    }

    /// Samples the sensors at the period boundary (call after [`Plant::run_period`]).
    pub fn sample(&mut self) -> Measurements {
        let i = self.machine.phase_currents();
        let phase_currents = self.current_sensors.measure(i);
        let dc_bus = self.bus_sensor.measure(self.inverter.dc_bus());
        Measurements {
            phase_currents,
            dc_bus,
            channels: self.current_sensors.config().channels,
        }
    }

    /// Averages over the last period (applied voltage, DC-link current and power).
    pub fn last_period(&self) -> PeriodReport {
        self.report
    }

    /// Periods run so far.
    pub fn periods(&self) -> u64 {
        self.periods
    }

    /// The machine (true speed, torque, currents, fluxes, energies).
    pub fn machine(&self) -> &InductionMachine {
        &self.machine
    }

    /// Mutable machine (set state, lock the rotor, change parameters).
    pub fn machine_mut(&mut self) -> &mut InductionMachine {
        &mut self.machine
    }

    /// The inverter.
    pub fn inverter(&self) -> &Inverter {
        &self.inverter
    }

    /// Mutable inverter.
    pub fn inverter_mut(&mut self) -> &mut Inverter {
        &mut self.inverter
    }

    /// Mutable current sensors (e.g. to replace them with another configuration).
    pub fn current_sensors_mut(&mut self) -> &mut CurrentSensors {
        &mut self.current_sensors
    }

    /// Mutable bus-voltage sensor.
    pub fn bus_sensor_mut(&mut self) -> &mut BusVoltageSensor {
        &mut self.bus_sensor
    }

    /// The load of the last period.
    pub fn load(&self) -> LoadTorque {
        self.load
    }

    /// True load torque at the present speed, N m.
    pub fn load_torque(&self) -> f32 {
        self.load.torque(self.machine.speed())
    }

    /// True stator current (i_alpha, i_beta), A.
    pub fn current_alpha_beta(&self) -> AlphaBeta {
        self.machine.current_alpha_beta()
    }

    /// True phase currents, A.
    pub fn phase_currents(&self) -> [f32; 3] {
        self.machine.phase_currents()
    }

    /// True stator current in the frame at electrical angle theta, given by its sin/cos:
    /// Park of (i_alpha, i_beta), A (the caller supplies sin/cos, no trig here).
    pub fn current_dq(&self, theta: SinCosValue) -> Dq {
        park(self.machine.current_alpha_beta(), theta)
    }

    /// True mechanical speed, rad/s.
    pub fn speed(&self) -> f32 {
        self.machine.speed()
    }

    /// True electromagnetic torque, N m.
    pub fn torque(&self) -> f32 {
        self.machine.torque()
    }
}

impl Default for Plant {
    fn default() -> Self {
        Self::paper_default(1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With phase b open, its current stays zero while the others carry current.
    #[test]
    fn an_open_phase_carries_no_current() {
        let mut p = Plant::ideal(MachineParams::paper_table1(), 300.0);
        p.set_open_phase(Some(1));
        for k in 0..200 {
            let th = k as f32 * 0.05;
            let d = [
                0.5 + 0.3 * libm_free_cos(th),
                0.5 + 0.3 * libm_free_cos(th - 2.094),
                0.5 + 0.3 * libm_free_cos(th + 2.094),
            ];
            p.run_period(d, true, LoadTorque::None);
            let i = p.phase_currents();
            assert!(i[1].abs() < 1e-4, "{i:?}");
        }
        assert!(p.phase_currents()[0].abs() > 0.1);
    }

    /// A DC vector into the machine at standstill: the current runs up until the
    /// comparator opens the gates, which then stay off (latched) whatever the command
    /// says, until the reset; the switch-off instant does not depend on the sub-step.
    #[test]
    fn the_comparator_opens_the_gates_and_latches() {
        let run = |substeps: u32, mode: PwmMode| {
            let mut p = Plant::paper_default(1);
            p.set_substeps(substeps);
            p.set_mode(mode);
            p.set_comparator(Some(ComparatorConfig::at(8.8)));
            p.set_watch_level(8.0);
            let mut peak = 0.0f32;
            let mut above = 0.0f32;
            for _ in 0..200 {
                p.run_period([1.0, 0.0, 0.0], true, LoadTorque::None);
                peak = peak.max(p.last_period().switching_peak_a);
                above += p.last_period().switching_above_watch_s;
                if p.comparator_trip().is_some() {
                    break;
                }
            }
            let trip = p.comparator_trip().expect("the comparator fired");
            (p, trip, peak, above)
        };
        let (mut p, trip, peak, above) = run(5, PwmMode::Averaged);
        assert!(trip.off_s - trip.crossing_s > 1.4e-6, "{trip:?}");
        // the gates went off within the delay: the current barely passed the level
        assert!(trip.current_a > 8.8 && trip.current_a < 8.9, "{trip:?}");
        assert!(peak <= trip.current_a + 1e-4 && peak > 8.8, "{peak}");
        // from 8 A to the switch-off: the current approaches its DC end value (about
        // 20 A) over several periods
        assert!(above > 200e-6 && above < 5e-3, "{above}");
        // latched: commanded on, the currents decay through the diodes
        for _ in 0..10 {
            p.run_period([1.0, 0.0, 0.0], true, LoadTorque::None);
            assert_eq!(p.last_period().switching_peak_a, 0.0);
        }
        assert!(comparator::max_abs(p.phase_currents()) < 0.5);
        p.reset_comparator();
        p.run_period([1.0, 0.0, 0.0], true, LoadTorque::None);
        assert!(p.last_period().switching_peak_a > 0.0);
        // the same instant with 10x finer sub-steps and at switching level
        for (n, mode) in [(50, PwmMode::Averaged), (5, PwmMode::Switched)] {
            let (_, fine, _, _) = run(n, mode);
            assert_eq!(fine.period, trip.period, "{fine:?} {trip:?}");
            assert!((fine.off_s - trip.off_s).abs() < 5e-6, "{fine:?} {trip:?}");
            assert!(fine.current_a > 8.8 && fine.current_a < 8.95, "{fine:?}");
        }
    }

    /// Without a comparator nothing changes: the period is the same as before it existed
    /// (gates on and off alike), and the report's peak follows the current.
    #[test]
    fn no_comparator_no_switch_off() {
        let mut p = Plant::paper_default(1);
        for _ in 0..40 {
            p.run_period([1.0, 0.0, 0.0], true, LoadTorque::None);
        }
        assert!(p.comparator_trip().is_none());
        assert!(comparator::max_abs(p.phase_currents()) > 9.0);
        assert!(p.last_period().switching_peak_a > 9.0);
        assert_eq!(p.last_period().switching_above_watch_s, 0.0);
    }

    /// cos by a short Taylor series after range reduction (tests only; no libm here).
    fn libm_free_cos(x: f32) -> f32 {
        let x = acim::math::wrap_angle(x);
        let x2 = x * x;
        1.0 - x2 / 2.0 + x2 * x2 / 24.0 - x2 * x2 * x2 / 720.0 + x2 * x2 * x2 * x2 / 40320.0
    }

    /// The plant's phase currents are the library's inverse Clarke of its alpha-beta
    /// current: a zero-sum set whose two-channel Clarke gives the state back.
    #[test]
    fn phase_currents_use_the_library_transforms() {
        let mut p = Plant::ideal(MachineParams::paper_table1(), 300.0);
        let mut st = p.machine().state();
        st.i_alpha = 1.0;
        st.i_beta = 2.0;
        p.machine_mut().set_state(st);
        let [a, b, c] = p.phase_currents();
        assert!((a + b + c).abs() < 1e-6);
        let i = acim::frames::clarke_two(a, b);
        assert!((i.alpha - 1.0).abs() < 1e-6 && (i.beta - 2.0).abs() < 1e-6);
    }
}
