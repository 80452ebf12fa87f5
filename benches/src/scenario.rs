//! The benchmark scenario, shared by the firmware bin (Cortex-M4F, QEMU or a board) and the
//! host tests: the real drive in closed loop with the motor model.
//!
//! ## Markers
//!
//! The regions inside the step are the drive's own (`Drive::step_probed` with a probe that
//! calls the markers, run on a clone of the drive with the same inputs: its duties must
//! equal the real step's bit for bit); `sincos` and the full-order baseline are measured
//! beside it on the same samples. Each region `R` is bracketed by calls to
//! `bench_begin_R` and `bench_end_R`:
//! `#[inline(never)] #[no_mangle]` functions with distinct bodies (so that no pass merges
//! them). The host runner finds their addresses in the ELF symbol table and counts the
//! instructions executed between the two calls in QEMU's execution log. Values cross the
//! markers through `core::hint::black_box` (inputs after `begin`, outputs before `end`), and
//! all state lives in memory that has escaped, so the compiler cannot move work out of a
//! region. With the `dwt` feature the markers read the DWT cycle counter instead.
//!
//! Regions are measured only on steps where the drive is `Running`.

// The marker symbols are `no_mangle` functions and a volatile store: the only unsafe code
// of the bench, allowed here and nowhere else (the workspace denies unsafe_code).
#![allow(unsafe_code)]

use core::hint::black_box;
use core::sync::atomic::AtomicU32;

use acim::drive::{
    Drive, DriveConfig, DriveInputs, DriveState, PwmOutput, StepProbe, StepRegion, TelemetryRate,
};
use acim::flux_observer::{FluxObserverConfig, FluxObserverDesign, FluxObserverState};
use acim::frames::{clarke_two, inverse_park, AlphaBeta, FastSinCos};
use acim::full_order::{FullOrderConfig, FullOrderDesign, FullOrderObserver};
use acim::math::RPM_TO_RAD_S;
use acim::svpwm::SvpwmConfig;
use acim_plant::{LoadTorque, Plant, PwmPreload};

/// Region names in marker-id order (id = index). `empty` calibrates the marker overhead.
pub const REGIONS: [&str; 21] = [
    "empty",
    "fault_checks",
    "sincos",
    "clarke_park",
    "observer_reduced",
    "observer_full_order",
    "rs_estimator",
    "flux_slip",
    "speed_pi",
    "current_pi",
    "svpwm",
    "drive_step",
    "overmodulation",
    "observer_flux",
    "two_rate_fast",
    "two_rate_tick",
    "two_rate_slow",
    "drive_step_loaded",
    "two_rate_fast_loaded",
    "two_rate_tick_loaded",
    "two_rate_slow_loaded",
];

/// Steps from `start()` on (magnetising, with the speed search, the inverter test at
/// start and the standstill Rs identification, is about 4400 steps), then this many
/// measured `Running` steps.
pub const MEASURED_STEPS: u32 = 2000;
/// Running steps from which the steady loaded point is measured: the ramp reaches
/// [`SPEED_TARGET_RPM`] after 1 s of running (5000 steps at 500 rpm/s) and the load has
/// been on since [`LOAD_FROM_STEP`]; 0.4 s later the speed and the estimators have
/// settled.
pub const LOADED_FROM_STEP: u32 = 7000;
/// Running steps measured at the steady loaded point (the `*_loaded` regions).
pub const LOADED_STEPS: u32 = 1000;
/// Upper bound on the whole run, steps.
pub const MAX_STEPS: u32 = 16000;
/// Speed target, rpm.
pub const SPEED_TARGET_RPM: f32 = 500.0;
/// Passive load (paper Fig. 7: 1.5 N m) applied from this measured step on.
pub const LOAD_FROM_STEP: u32 = 1000;
/// Load torque, N m.
pub const LOAD_TORQUE: f32 = 1.5;
/// RK4 sub-steps of the plant per period (the model's default is 10; 4 keeps the QEMU
/// trace short and |lambda h| < 0.03).
pub const PLANT_SUBSTEPS: u32 = 4;

/// Last marker id written (the markers' side effect; also keeps their bodies distinct).
pub static MARK: AtomicU32 = AtomicU32::new(0);

/// A volatile write of the marker id: it cannot be optimised away, so the marker bodies
/// stay distinct and no pass merges two markers into one address.
#[inline(always)]
fn mark(id: u32) {
    // SAFETY: `as_ptr` points to the static's valid, aligned u32; a volatile write of a
    // plain u32 from the only thread.
    unsafe { MARK.as_ptr().write_volatile(id) }
}

#[cfg(all(feature = "dwt", target_os = "none"))]
pub mod dwt {
    //! Cycle statistics per region from DWT CYCCNT (board path).
    use super::REGIONS;
    use core::cell::RefCell;
    use cortex_m::interrupt::Mutex;

    /// min, max, sum, count per region.
    #[derive(Clone, Copy)]
    pub struct Stat {
        pub min: u32,
        pub max: u32,
        pub sum: u64,
        pub n: u32,
    }
    pub static START: Mutex<RefCell<u32>> = Mutex::new(RefCell::new(0));
    pub static STATS: Mutex<RefCell<[Stat; REGIONS.len()]>> = Mutex::new(RefCell::new(
        [Stat {
            min: u32::MAX,
            max: 0,
            sum: 0,
            n: 0,
        }; REGIONS.len()],
    ));

    #[inline(always)]
    pub fn now() -> u32 {
        cortex_m::peripheral::DWT::cycle_count()
    }
    #[inline(always)]
    pub fn begin() {
        cortex_m::interrupt::free(|cs| *START.borrow(cs).borrow_mut() = now());
    }
    #[inline(always)]
    pub fn end(id: usize) {
        let t = now();
        cortex_m::interrupt::free(|cs| {
            let d = t.wrapping_sub(*START.borrow(cs).borrow());
            let mut s = STATS.borrow(cs).borrow_mut();
            if let Some(st) = s.get_mut(id) {
                st.min = st.min.min(d);
                st.max = st.max.max(d);
                st.sum += d as u64;
                st.n += 1;
            }
        });
    }
}

macro_rules! markers {
    ($( $id:literal => $begin:ident, $end:ident; )*) => {
        $(
            #[inline(never)]
            #[no_mangle]
            pub extern "C" fn $begin() {
                mark(2 * $id);
                #[cfg(all(feature = "dwt", target_os = "none"))]
                dwt::begin();
                black_box(());
            }
            #[inline(never)]
            #[no_mangle]
            pub extern "C" fn $end() {
                #[cfg(all(feature = "dwt", target_os = "none"))]
                dwt::end($id);
                mark(2 * $id + 1);
                black_box(());
            }
        )*
    };
}

markers! {
    0 => bench_begin_empty, bench_end_empty;
    1 => bench_begin_fault_checks, bench_end_fault_checks;
    2 => bench_begin_sincos, bench_end_sincos;
    3 => bench_begin_clarke_park, bench_end_clarke_park;
    4 => bench_begin_observer_reduced, bench_end_observer_reduced;
    5 => bench_begin_observer_full_order, bench_end_observer_full_order;
    6 => bench_begin_rs_estimator, bench_end_rs_estimator;
    7 => bench_begin_flux_slip, bench_end_flux_slip;
    8 => bench_begin_speed_pi, bench_end_speed_pi;
    9 => bench_begin_current_pi, bench_end_current_pi;
    10 => bench_begin_svpwm, bench_end_svpwm;
    11 => bench_begin_drive_step, bench_end_drive_step;
    12 => bench_begin_overmodulation, bench_end_overmodulation;
    13 => bench_begin_observer_flux, bench_end_observer_flux;
    14 => bench_begin_two_rate_fast, bench_end_two_rate_fast;
    15 => bench_begin_two_rate_tick, bench_end_two_rate_tick;
    16 => bench_begin_two_rate_slow, bench_end_two_rate_slow;
    17 => bench_begin_drive_step_loaded, bench_end_drive_step_loaded;
    18 => bench_begin_two_rate_fast_loaded, bench_end_two_rate_fast_loaded;
    19 => bench_begin_two_rate_tick_loaded, bench_end_two_rate_tick_loaded;
    20 => bench_begin_two_rate_slow_loaded, bench_end_two_rate_slow_loaded;
}

/// Calls the marker pair of each region of `Drive::step_probed`.
pub struct MarkerProbe;

impl StepProbe for MarkerProbe {
    #[inline(always)]
    fn begin(&mut self, region: StepRegion) {
        match region {
            StepRegion::FaultChecks => bench_begin_fault_checks(),
            StepRegion::ClarkePark => bench_begin_clarke_park(),
            StepRegion::ObserverReduced => bench_begin_observer_reduced(),
            StepRegion::RsEstimator => bench_begin_rs_estimator(),
            StepRegion::FluxSlip => bench_begin_flux_slip(),
            StepRegion::SpeedPi => bench_begin_speed_pi(),
            StepRegion::CurrentPi => bench_begin_current_pi(),
            StepRegion::Svpwm => bench_begin_svpwm(),
        }
    }
    #[inline(always)]
    fn end(&mut self, region: StepRegion) {
        match region {
            StepRegion::FaultChecks => bench_end_fault_checks(),
            StepRegion::ClarkePark => bench_end_clarke_park(),
            StepRegion::ObserverReduced => bench_end_observer_reduced(),
            StepRegion::RsEstimator => bench_end_rs_estimator(),
            StepRegion::FluxSlip => bench_end_flux_slip(),
            StepRegion::SpeedPi => bench_end_speed_pi(),
            StepRegion::CurrentPi => bench_end_current_pi(),
            StepRegion::Svpwm => bench_end_svpwm(),
        }
    }
}

/// The configuration benchmarked at one rate: the project defaults with the Rs estimator
/// on (so the step contains every block of the paper's scheme) and every stage every
/// period (`DriveConfig.loops.slow_period` 0: the whole step, which the two-rate run's
/// fast periods and slow ticks are measured against).
pub fn bench_config() -> DriveConfig {
    let mut c = DriveConfig::paper_defaults();
    c.estimation.rs_estimation = true;
    c.loops.slow_period = 0.0;
    c
}

/// The slow task's period of the two-rate run, s (1 kHz).
pub const TWO_RATE_SLOW_PERIOD: f32 = acim::design::TYPICAL_SLOW_PERIOD;

/// [`bench_config`] with a 1 kHz slow task (`DriveConfig.loops.slow_period`): the two-rate
/// run measures its fast periods and its slow ticks apart.
pub fn bench_config_two_rates() -> DriveConfig {
    let mut c = bench_config();
    c.loops.slow_period = TWO_RATE_SLOW_PERIOD;
    c
}

/// The baseline full-order observer and the flux observer, run as passengers on the
/// drive's samples and its applied voltage.
pub struct Passenger {
    cfg: FullOrderConfig,
    /// Observer state.
    pub full: FullOrderObserver,
    flux_cfg: FluxObserverConfig,
    /// The flux observer's state.
    pub flux: FluxObserverState,
    /// The stator resistance the flux observer assumes (the machine's), ohm.
    rs: f32,
    /// The flux of the drive's torque constant (its reference), Wb.
    torque_flux: f32,
    /// alpha-beta voltage applied over the coming period (the previous command), V.
    applied: (f32, f32),
    /// The drive's modulator configuration, for the overmodulation region.
    pwm: SvpwmConfig,
}

impl Passenger {
    /// The flux observer's step on the measured alpha-beta current (A), the voltage
    /// applied over the coming period and the machine's Rs and flux.
    #[inline(always)]
    fn observe_flux(&mut self, i_alpha: f32, i_beta: f32) {
        self.flux.update(
            &self.flux_cfg,
            self.applied,
            (i_alpha, i_beta),
            self.rs,
            self.torque_flux,
        );
    }

    fn new(cfg: &DriveConfig) -> Option<Self> {
        let m = cfg.machine;
        Some(Self {
            cfg: FullOrderConfig::new(
                &m,
                FullOrderDesign::paper_defaults(&m),
                cfg.loops.control_period,
            )
            .ok()?,
            full: FullOrderObserver::new(),
            flux_cfg: FluxObserverConfig::new(
                &m,
                FluxObserverDesign::defaults(
                    cfg.limits.max_speed,
                    m.magnetizing_inductance() * cfg.loops.flux_current,
                ),
                cfg.loops.control_period,
            )
            .ok()?,
            flux: FluxObserverState::new(),
            rs: m.stator_resistance(),
            torque_flux: m.magnetizing_inductance() * cfg.loops.flux_current,
            applied: (0.0, 0.0),
            pwm: SvpwmConfig::new(
                cfg.inverter.dead_time,
                cfg.loops.control_period,
                cfg.inverter.device_drop,
                cfg.inverter.dead_time_current_band,
            ),
        })
    }

    /// Speed estimate, rad/s.
    pub fn speed(&self) -> f32 {
        self.full.speed(&self.cfg)
    }

    /// The flux observer's speed estimate, rad/s.
    pub fn flux_speed(&self) -> f32 {
        self.flux.speed(&self.flux_cfg)
    }
}

/// The probed regions of one running step (on a clone of the drive), `sincos` alone, and
/// the full-order observer on the same samples. Returns the clone's output.
#[inline(never)]
#[no_mangle]
pub fn bench_regions_step(
    twin: &mut Drive,
    inp: &DriveInputs,
    passenger: &mut Passenger,
) -> PwmOutput {
    let twin = black_box(twin);
    let angle = twin.telemetry().angle;
    bench_begin_sincos();
    black_box(FastSinCos::eval(black_box(angle)));
    bench_end_sincos();

    let i_ab = clarke_two(inp.phase_currents[0], inp.phase_currents[1]);
    let p = black_box(&mut *passenger);
    bench_begin_observer_full_order();
    p.full
        .update(&p.cfg, p.applied.0, p.applied.1, i_ab.alpha, i_ab.beta);
    bench_end_observer_full_order();
    let p = black_box(&mut *passenger);
    bench_begin_observer_flux();
    p.observe_flux(i_ab.alpha, i_ab.beta);
    bench_end_observer_flux();

    // the overmodulating modulator alone (not in the drive's default step): this
    // step's command lengthened to 1.05 x the linear limit, at the measured bus
    let v = twin.telemetry().voltage;
    let rot = FastSinCos::eval(angle);
    let v_ab = inverse_park(v, rot);
    let norm = (v_ab.alpha * v_ab.alpha + v_ab.beta * v_ab.beta).max(1e-6);
    let k = 1.05 * acim::svpwm::linear_limit(inp.dc_bus) / acim::math::sqrt(norm);
    let v_om = AlphaBeta {
        alpha: v_ab.alpha * k,
        beta: v_ab.beta * k,
    };
    let inv_bus = 1.0 / inp.dc_bus.max(1.0);
    let pwm = passenger.pwm;
    let currents = black_box(inp.phase_currents);
    bench_begin_overmodulation();
    black_box(acim::svpwm::overmodulate(
        black_box(&pwm),
        black_box(v_om),
        black_box(inp.dc_bus),
        black_box(inv_bus),
        currents,
    ));
    bench_end_overmodulation();

    let out = twin.step_probed(black_box(inp), &mut MarkerProbe);
    black_box(out)
}

/// The whole drive step, as the firmware calls it (also the root of the static scan for
/// panic paths and f64 calls).
#[inline(never)]
#[no_mangle]
pub fn bench_region_drive_step(drive: &mut Drive, inp: &DriveInputs, on: bool) -> PwmOutput {
    if on {
        bench_begin_drive_step();
    }
    let out = drive.step(black_box(inp));
    let out = black_box(out);
    if on {
        bench_end_drive_step();
    }
    out
}

/// One step of the two-rate drive, as the firmware calls it: the fast part
/// (`Drive::step_fast`), measured as a fast period (`two_rate_fast`) or a slow tick
/// (`two_rate_tick`), then a tick's slow task (`Drive::run_slow`, `two_rate_slow`), which
/// the firmware may run in a lower-priority interrupt.
#[inline(never)]
#[no_mangle]
pub fn bench_region_two_rates(drive: &mut Drive, inp: &DriveInputs, on: bool) -> PwmOutput {
    let tick = drive.slow_tick_due();
    if on {
        if tick {
            bench_begin_two_rate_tick();
        } else {
            bench_begin_two_rate_fast();
        }
    }
    let out = drive.step_fast(black_box(inp));
    let out = black_box(out);
    if on {
        if tick {
            bench_end_two_rate_tick();
        } else {
            bench_end_two_rate_fast();
        }
    }
    if drive.slow_pending() {
        if on {
            bench_begin_two_rate_slow();
        }
        drive.run_slow();
        if on {
            bench_end_two_rate_slow();
        }
    }
    out
}

/// [`bench_region_drive_step`] at the steady loaded point (`drive_step_loaded`): every
/// estimator path live (the Rs law, the trackers at speed under load).
#[inline(never)]
#[no_mangle]
pub fn bench_region_drive_step_loaded(drive: &mut Drive, inp: &DriveInputs, on: bool) -> PwmOutput {
    if on {
        bench_begin_drive_step_loaded();
    }
    let out = drive.step(black_box(inp));
    let out = black_box(out);
    if on {
        bench_end_drive_step_loaded();
    }
    out
}

/// [`bench_region_two_rates`] at the steady loaded point (`two_rate_fast_loaded`,
/// `two_rate_tick_loaded`, `two_rate_slow_loaded`).
#[inline(never)]
#[no_mangle]
pub fn bench_region_two_rates_loaded(drive: &mut Drive, inp: &DriveInputs, on: bool) -> PwmOutput {
    let tick = drive.slow_tick_due();
    if on {
        if tick {
            bench_begin_two_rate_tick_loaded();
        } else {
            bench_begin_two_rate_fast_loaded();
        }
    }
    let out = drive.step_fast(black_box(inp));
    let out = black_box(out);
    if on {
        if tick {
            bench_end_two_rate_tick_loaded();
        } else {
            bench_end_two_rate_fast_loaded();
        }
    }
    if drive.slow_pending() {
        if on {
            bench_begin_two_rate_slow_loaded();
        }
        drive.run_slow();
        if on {
            bench_end_two_rate_slow_loaded();
        }
    }
    out
}

/// The calibration region: begin immediately followed by end, eight times.
#[inline(never)]
#[no_mangle]
pub fn bench_calibrate() {
    for _ in 0..8 {
        bench_begin_empty();
        bench_end_empty();
    }
}

/// What a run found (printed by the firmware, checked by the host tests).
#[derive(Clone, Copy, Debug, Default)]
pub struct Summary {
    /// Steps run in all.
    pub steps: u32,
    /// Running steps measured.
    pub measured: u32,
    /// Steps where the probed clone's duties differed (bitwise) from the drive's.
    pub mismatches: u32,
    /// Steps where the probed clone faulted (expected 0).
    pub replica_faults: u32,
    /// Whether the drive faulted.
    pub drive_faulted: bool,
    /// True speed at the end, rpm.
    pub true_rpm: f32,
    /// Reduced-order estimate at the end, rpm.
    pub reduced_rpm: f32,
    /// Full-order estimate at the end, rpm.
    pub full_rpm: f32,
    /// Mean |full-order - true| over the measured steps, rpm.
    pub full_mean_abs_err_rpm: f32,
    /// Mean |reduced-order - true| over the measured steps, rpm.
    pub reduced_mean_abs_err_rpm: f32,
    /// Mean |flux observer - true| over the measured steps, rpm.
    pub flux_mean_abs_err_rpm: f32,
    /// Running steps of the two-rate run measured.
    pub two_rate_measured: u32,
    /// Whether the two-rate drive faulted.
    pub two_rate_faulted: bool,
    /// Steps measured at the steady loaded point.
    pub loaded_measured: u32,
    /// True speed at the end of the steady loaded point, rpm.
    pub loaded_true_rpm: f32,
    /// Steps of the two-rate run measured at the steady loaded point.
    pub two_rate_loaded_measured: u32,
}

/// Runs the scenario: start, magnetise, ramp to [`SPEED_TARGET_RPM`], load step; the
/// regions are measured on [`MEASURED_STEPS`] running steps.
pub fn run() -> Summary {
    let cfg = black_box(bench_config());
    let mut drive = match Drive::new(cfg) {
        Ok(d) => d,
        Err(_) => return Summary::default(),
    };
    let mut passenger = match Passenger::new(&cfg) {
        Some(p) => p,
        None => return Summary::default(),
    };
    let mut plant = Plant::paper_default(1);
    plant.set_substeps(PLANT_SUBSTEPS);
    // the duties computed at a step act over the period after (preloaded compare
    // registers), the timing the drive compensates for
    let mut pwm = PwmPreload::new();
    let target = SPEED_TARGET_RPM * RPM_TO_RAD_S;
    let _ = drive.set_speed_target(target);
    let _ = drive.start();
    let drive = black_box(&mut drive);

    bench_calibrate();

    let mut s = Summary::default();
    let mut err_full = 0.0f32;
    let mut err_red = 0.0f32;
    let mut err_flux = 0.0f32;
    let ts = cfg.loops.control_period;
    while s.steps < MAX_STEPS && s.measured < MEASURED_STEPS {
        let meas = plant.sample();
        let inp = DriveInputs {
            phase_currents: meas.phase_currents,
            dc_bus: meas.dc_bus,
        };
        let on = drive.state() == DriveState::Running;
        let twin_out = if on {
            let mut twin = drive.clone();
            let o = bench_regions_step(&mut twin, &inp, &mut passenger);
            if twin.state() == DriveState::Fault {
                s.replica_faults += 1;
            }
            Some(o)
        } else {
            // the passenger observes from the first step (unmeasured before Running)
            let i_ab = clarke_two(inp.phase_currents[0], inp.phase_currents[1]);
            let p = &mut passenger;
            p.full
                .update(&p.cfg, p.applied.0, p.applied.1, i_ab.alpha, i_ab.beta);
            p.observe_flux(i_ab.alpha, i_ab.beta);
            None
        };
        let out = bench_region_drive_step(drive, &inp, on);
        if let Some(t) = twin_out {
            if t.duties.map(f32::to_bits) != out.duties.map(f32::to_bits) {
                s.mismatches += 1;
            }
        }
        // the voltage this command applies over the next period, for the passenger
        let t = drive.telemetry();
        let lead = t.angle + t.stator_frequency * ts * cfg.inverter.delay_periods;
        let v = inverse_park(t.voltage, FastSinCos::eval(lead));
        passenger.applied = (v.alpha, v.beta);

        let load = if s.measured >= LOAD_FROM_STEP {
            LoadTorque::Passive {
                torque: LOAD_TORQUE,
            }
        } else {
            LoadTorque::None
        };
        plant.run_pwm_period(pwm.advance(out), load);
        s.steps += 1;
        if on {
            s.measured += 1;
            let w = plant.speed();
            err_full += (passenger.speed() - w).abs();
            err_red += (drive.telemetry().speed_estimate - w).abs();
            err_flux += (passenger.flux_speed() - w).abs();
        }
        if drive.state() == DriveState::Fault {
            s.drive_faulted = true;
            break;
        }
    }
    let n = if s.measured > 0 {
        s.measured as f32
    } else {
        1.0
    };
    s.true_rpm = plant.speed() / RPM_TO_RAD_S;
    s.reduced_rpm = drive.telemetry().speed_estimate / RPM_TO_RAD_S;
    s.full_rpm = passenger.speed() / RPM_TO_RAD_S;
    // on to the steady loaded point (unmeasured), then the step measured there
    let mut running = s.measured;
    while !s.drive_faulted && s.steps < MAX_STEPS && running < LOADED_FROM_STEP + LOADED_STEPS {
        let meas = plant.sample();
        let inp = DriveInputs {
            phase_currents: meas.phase_currents,
            dc_bus: meas.dc_bus,
        };
        let on = drive.state() == DriveState::Running && running >= LOADED_FROM_STEP;
        let out = bench_region_drive_step_loaded(drive, &inp, on);
        plant.run_pwm_period(
            pwm.advance(out),
            LoadTorque::Passive {
                torque: LOAD_TORQUE,
            },
        );
        s.steps += 1;
        if drive.state() == DriveState::Running {
            running += 1;
        }
        if on {
            s.loaded_measured += 1;
        }
        if drive.state() == DriveState::Fault {
            s.drive_faulted = true;
        }
    }
    s.loaded_true_rpm = plant.speed() / RPM_TO_RAD_S;
    s.full_mean_abs_err_rpm = err_full / n / RPM_TO_RAD_S;
    s.reduced_mean_abs_err_rpm = err_red / n / RPM_TO_RAD_S;
    s.flux_mean_abs_err_rpm = err_flux / n / RPM_TO_RAD_S;
    let (measured, loaded, faulted) = run_two_rates();
    s.two_rate_measured = measured;
    s.two_rate_loaded_measured = loaded;
    s.two_rate_faulted = faulted;
    s
}

/// The same scenario closed by the two-rate drive ([`bench_config_two_rates`]), with its
/// own plant, on to the steady loaded point: (running steps measured on the ramp, at the
/// loaded point, whether it faulted). The drive records its telemetry at the slow ticks
/// (`TelemetryRate::SlowTick`), as the firmware's does while it samples the telemetry a
/// slow period or more apart (10 Hz by default); this run reads none.
fn run_two_rates() -> (u32, u32, bool) {
    let cfg = black_box(bench_config_two_rates());
    let Ok(mut drive) = Drive::new(cfg) else {
        return (0, 0, true);
    };
    drive.set_telemetry_rate(TelemetryRate::SlowTick);
    let mut plant = Plant::paper_default(1);
    plant.set_substeps(PLANT_SUBSTEPS);
    let mut pwm = PwmPreload::new();
    let _ = drive.set_speed_target(SPEED_TARGET_RPM * RPM_TO_RAD_S);
    let _ = drive.start();
    let drive = black_box(&mut drive);
    let (mut steps, mut measured, mut loaded) = (0, 0, 0);
    while steps < MAX_STEPS && measured < LOADED_FROM_STEP + LOADED_STEPS {
        let meas = plant.sample();
        let inp = DriveInputs {
            phase_currents: meas.phase_currents,
            dc_bus: meas.dc_bus,
        };
        let running = drive.state() == DriveState::Running;
        // the ramp's first measured steps, then the steady loaded point
        let out = if measured < MEASURED_STEPS {
            bench_region_two_rates(drive, &inp, running)
        } else {
            let on = running && measured >= LOADED_FROM_STEP;
            if on {
                loaded += 1;
            }
            bench_region_two_rates_loaded(drive, &inp, on)
        };
        let on = running;
        let load = if measured >= LOAD_FROM_STEP {
            LoadTorque::Passive {
                torque: LOAD_TORQUE,
            }
        } else {
            LoadTorque::None
        };
        plant.run_pwm_period(pwm.advance(out), load);
        steps += 1;
        if on {
            measured += 1;
        }
        if drive.state() == DriveState::Fault {
            return (measured.min(MEASURED_STEPS), loaded, true);
        }
    }
    (measured.min(MEASURED_STEPS), loaded, false)
}
