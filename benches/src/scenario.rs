//! The benchmark scenario, shared by the firmware bin (Cortex-M4F, QEMU or a board) and the
//! host tests: the real drive in closed loop with the motor model, plus a "shadow" copy
//! of the drive's pipeline built from the same public blocks and run on the same samples,
//! so that each block can be bracketed by marker calls on its own, in the order of
//! `Drive::step`. The shadow's duties are compared bit for bit with the drive's every
//! step (a mismatch means the replica no longer reflects the drive).
//!
//! ## Markers
//!
//! Each region `R` is bracketed by calls to `bench_begin_R` and `bench_end_R`:
//! `#[inline(never)] #[no_mangle]` functions with distinct bodies (so that no pass merges
//! them). The host runner finds their addresses in the ELF symbol table and counts the
//! instructions executed between the two calls in QEMU's execution log. Values cross the
//! markers through `core::hint::black_box` (inputs after `begin`, outputs before `end`), and
//! all state lives in memory that has escaped, so the compiler cannot move work out of a
//! region. With the `dwt` feature the markers read the DWT cycle counter instead.
//!
//! Regions are measured only on steps where the drive is `Running`.

use core::hint::black_box;
use core::sync::atomic::AtomicU32;

use acim::drive::{CurrentSensing, Drive, DriveConfig, DriveInputs, DriveState, PwmOutput};
use acim::flux::{FluxModel, FluxModelConfig};
use acim::frames::{
    clarke_three, clarke_two, inverse_clarke, inverse_park, park, AlphaBeta, Dq, FastSinCos,
    SinCosValue,
};
use acim::full_order::{FullOrderConfig, FullOrderDesign, FullOrderObserver};
use acim::math::{clamp, is_finite, sqrt, RPM_TO_RAD_S};
use acim::model::{LoadTorque, Plant};
use acim::observer::{ObserverConfig, ObserverInputs, ReducedOrderObserver};
use acim::pi::{PiConfig, PiController};
use acim::rs_estimator::{RsEstimator, RsEstimatorConfig, RsEstimatorInputs};
use acim::svpwm::{linear_limit, modulate, SvpwmConfig};

/// Region names in marker-id order (id = index). `empty` calibrates the marker overhead.
pub const REGIONS: [&str; 12] = [
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
];

/// Steps from `start()` on (magnetising is about 1350 steps), then this many measured
/// `Running` steps.
pub const MEASURED_STEPS: u32 = 2000;
/// Upper bound on the whole run, steps.
pub const MAX_STEPS: u32 = 6000;
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
}

/// Calls `$begin` / `$end` around the block when `$on`.
macro_rules! region {
    ($on:expr, $begin:ident, $end:ident, $body:block) => {{
        if $on {
            $begin();
        }
        let r = $body;
        if $on {
            $end();
        }
        r
    }};
}

/// The configuration benchmarked: the project defaults with the Rs estimator on (so the
/// step contains every block of the paper's scheme).
pub fn bench_config() -> DriveConfig {
    let mut c = DriveConfig::paper_defaults();
    c.rs_estimation = true;
    c
}

/// A replica of `Drive::step` (Running and Magnetizing paths, two-phase sensing) built
/// from the crate's public blocks, with a marker pair around each block.
pub struct Shadow {
    cfg: DriveConfig,
    pi_d: PiConfig,
    pi_q: PiConfig,
    pi_speed: PiConfig,
    flux_cfg: FluxModelConfig,
    obs_cfg: ObserverConfig,
    rs_cfg: RsEstimatorConfig,
    pwm_cfg: SvpwmConfig,
    full_cfg: FullOrderConfig,
    i_sd_ref: f32,
    settled_flux: f32,
    sigma_ls: f32,
    referred_rotor_resistance: f32,
    inv_rotor_time_constant: f32,
    pole_pairs: f32,
    ramp_step: f32,
    orientation_gain_per_flux: f32,
    orientation_fade_start: f32,
    orientation_inv_fade_width: f32,
    orientation_limit: f32,
    overcurrent_trip: f32,
    stall_steps: u32,
    rs_timeout_steps: u32,
    rs_settle_steps: u32,
    implausible_limit: u32,
    residual_filter: f32,
    rs_settled_error: f32,
    // state
    implausible_steps: u32,
    magnetizing_steps: u32,
    rs_settled_steps: u32,
    filtered_residual: f32,
    running: bool,
    speed_target: f32,
    speed_reference: f32,
    speed_ctl: PiController,
    d_ctl: PiController,
    q_ctl: PiController,
    flux: FluxModel,
    observer: ReducedOrderObserver,
    rs: RsEstimator,
    applied_voltage: Dq,
    applied_alpha_beta: AlphaBeta,
    stall_counter: u32,
    /// The baseline observer, run as a passenger on the same samples.
    pub full: FullOrderObserver,
    /// Number of fault conditions the replica's checks found (expected 0).
    pub faults_seen: u32,
}

impl Shadow {
    /// Precomputes everything the way `Drive::with_sincos` does.
    pub fn new(cfg: DriveConfig, drive: &Drive) -> Option<Self> {
        let m = cfg.machine;
        let ts = cfg.control_period;
        let i_d = cfg.flux_current;
        let flux_reference = drive.flux_reference();
        let i_sq_limit = drive.torque_current_limit();
        let v_static = linear_limit(cfg.dc_bus_max);
        let mut rs_cfg = RsEstimatorConfig::new(&m, ts, cfg.rs_convergence_time, i_d);
        rs_cfg.flux_tolerance = cfg.flux_tolerance;
        rs_cfg.adapt = cfg.rs_estimation;
        rs_cfg.max_stator_frequency = cfg.rs_max_frequency;
        let full_cfg = FullOrderConfig::new(&m, FullOrderDesign::paper_defaults(&m), ts).ok()?;
        Some(Self {
            pi_d: PiConfig::current_loop(&m, cfg.current_bandwidth, ts, v_static),
            pi_q: PiConfig::current_loop(&m, cfg.current_bandwidth, ts, v_static),
            pi_speed: PiConfig::speed_loop(&m, flux_reference, cfg.speed_bandwidth, ts, i_sq_limit),
            flux_cfg: FluxModelConfig::new(&m, ts, flux_reference),
            obs_cfg: *drive.observer_config(),
            rs_cfg,
            pwm_cfg: SvpwmConfig::new(
                cfg.dead_time,
                ts,
                cfg.device_drop,
                cfg.dead_time_current_band,
            ),
            full_cfg,
            i_sd_ref: i_d,
            settled_flux: flux_reference * (1.0 - cfg.flux_tolerance),
            sigma_ls: m.transient_inductance(),
            referred_rotor_resistance: m.referred_rotor_resistance(),
            inv_rotor_time_constant: 1.0 / m.rotor_time_constant(),
            pole_pairs: m.pole_pairs_f32(),
            ramp_step: cfg.speed_ramp * ts,
            orientation_gain_per_flux: cfg.orientation_gain / flux_reference,
            orientation_fade_start: cfg.orientation_fade.0,
            orientation_inv_fade_width: 1.0 / (cfg.orientation_fade.1 - cfg.orientation_fade.0),
            orientation_limit: 0.25 * cfg.max_speed * m.pole_pairs_f32(),
            overcurrent_trip: cfg.overcurrent_trip,
            stall_steps: (cfg.stall_time / ts) as u32,
            rs_timeout_steps: (cfg.rs_identification_timeout / ts) as u32,
            rs_settle_steps: (0.05 / ts) as u32,
            implausible_limit: (0.02 / ts) as u32,
            residual_filter: (ts / 0.02).min(1.0),
            rs_settled_error: 0.003 * i_d,
            implausible_steps: 0,
            magnetizing_steps: 0,
            rs_settled_steps: 0,
            filtered_residual: 0.0,
            running: false,
            speed_target: 0.0,
            speed_reference: 0.0,
            speed_ctl: PiController::new(),
            d_ctl: PiController::new(),
            q_ctl: PiController::new(),
            flux: FluxModel::new(),
            observer: ReducedOrderObserver::new(),
            rs: RsEstimator::new(cfg.rs_initial),
            applied_voltage: Dq::default(),
            applied_alpha_beta: AlphaBeta::default(),
            stall_counter: 0,
            full: FullOrderObserver::new(),
            faults_seen: 0,
            cfg,
        })
    }

    /// Same clamp as `Drive::set_speed_target`.
    pub fn set_speed_target(&mut self, speed: f32) {
        let lim = 0.9 * self.cfg.max_speed;
        self.speed_target = clamp(speed, -lim, lim);
    }

    /// Estimated speed of the reduced-order observer, rad/s.
    pub fn speed_estimate(&self) -> f32 {
        self.observer.speed_estimate
    }

    /// Estimated speed of the full-order observer, rad/s.
    pub fn full_order_speed(&self) -> f32 {
        self.full.speed(&self.full_cfg)
    }

    /// `Drive::check_inputs` (two-phase sensing) plus the estimator plausibility checks
    /// of the step, on the estimates of the previous step; returns true when anything
    /// would fault.
    #[inline(always)]
    fn checks(&self, inp: &DriveInputs) -> bool {
        let [a, b, c_meas] = inp.phase_currents;
        let c = match self.cfg.current_sensing {
            CurrentSensing::TwoPhase => -a - b,
            CurrentSensing::ThreePhase => c_meas,
        };
        if !(is_finite(a) && is_finite(b) && is_finite(c) && is_finite(inp.dc_bus)) {
            return true;
        }
        let trip = self.overcurrent_trip;
        if a.abs() > trip || b.abs() > trip || c.abs() > trip {
            return true;
        }
        if inp.dc_bus > self.cfg.dc_bus_max || inp.dc_bus < self.cfg.dc_bus_min {
            return true;
        }
        let speed_est = self.observer.speed_estimate;
        if !(is_finite(speed_est)
            && is_finite(self.observer.load_torque_estimate)
            && is_finite(self.observer.current_estimate))
            || (self.cfg.rs_estimation && self.rs.at_bound)
        {
            return true;
        }
        speed_est.abs() > self.cfg.max_speed
    }

    /// The drive's persistence counter of an implausible load estimate.
    #[inline(always)]
    fn implausible(&mut self) -> bool {
        self.implausible_steps =
            if self.observer.load_torque_estimate.abs() > self.cfg.max_load_torque_estimate {
                self.implausible_steps.saturating_add(1)
            } else {
                0
            };
        self.implausible_steps > self.implausible_limit
    }

    /// One step of the replica. `on`: call the region markers.
    #[inline(never)]
    pub fn step(&mut self, inp: &DriveInputs, on: bool) -> [f32; 3] {
        // input checks and estimator plausibility (the latter on the previous step's
        // estimates: same work as the drive's, done here in one region)
        let fault = region!(on, bench_begin_fault_checks, bench_end_fault_checks, {
            let s = black_box(&mut *self);
            let a = s.checks(black_box(inp));
            let b = s.implausible();
            black_box(a || b)
        });
        if fault {
            self.faults_seen += 1;
        }
        let ts = self.cfg.control_period;

        // sin/cos alone (result discarded; the next region computes it again)
        region!(on, bench_begin_sincos, bench_end_sincos, {
            black_box(FastSinCos::eval(black_box(self.flux.angle)));
        });

        // Clarke + Park with sin/cos
        let (i_ab, sc, i) = region!(on, bench_begin_clarke_park, bench_end_clarke_park, {
            let s = black_box(&*self);
            let [a, b, c] = black_box(inp.phase_currents);
            let i_ab = match s.cfg.current_sensing {
                CurrentSensing::TwoPhase => clarke_two(a, b),
                CurrentSensing::ThreePhase => clarke_three(a, b, c),
            };
            let sc = FastSinCos::eval(s.flux.angle);
            let i = park(i_ab, sc);
            black_box((i_ab, sc, i))
        });
        let magnetizing = !self.running;

        // 3. reduced-order observer
        if !magnetizing {
            region!(
                on,
                bench_begin_observer_reduced,
                bench_end_observer_reduced,
                {
                    let s = black_box(&mut *self);
                    let rseq = s.rs.stator_resistance_estimate + s.referred_rotor_resistance;
                    s.observer.update(
                        &s.obs_cfg,
                        &ObserverInputs {
                            i_sq: i.q,
                            i_sd: i.d,
                            stator_frequency: s.flux.stator_frequency,
                            v_sq: s.applied_voltage.q,
                            rotor_flux: s.flux.rotor_flux,
                            inv_rotor_flux: s.flux.inv_rotor_flux,
                            equivalent_resistance: rseq,
                        },
                    );
                    black_box(&*s);
                }
            );
        }

        // the baseline, side by side: full-order observer on alpha-beta quantities
        region!(
            on,
            bench_begin_observer_full_order,
            bench_end_observer_full_order,
            {
                let s = black_box(&mut *self);
                let v = s.applied_alpha_beta;
                s.full
                    .update(&s.full_cfg, v.alpha, v.beta, i_ab.alpha, i_ab.beta);
                black_box(&*s);
            }
        );
        let speed_est = self.observer.speed_estimate;

        // 4. stator resistance: the eq. (20) current model runs every step, the
        // resistance adapts inside its gate; the residual filter of the drive
        let flux_settled = self.flux.rotor_flux >= self.settled_flux;
        let ws_prev = self.flux.stator_frequency;
        region!(on, bench_begin_rs_estimator, bench_end_rs_estimator, {
            let s = black_box(&mut *self);
            s.rs.update(
                &s.rs_cfg,
                &RsEstimatorInputs {
                    i_sd: i.d,
                    i_sq: i.q,
                    v_sd: s.applied_voltage.d,
                    stator_frequency: ws_prev,
                    flux_settled,
                },
            );
            s.filtered_residual += s.residual_filter * (s.rs.current_error - s.filtered_residual);
            black_box(&*s);
        });
        let rs_hat = self.rs.stator_resistance_estimate;

        // 5. flux model, slip, angle
        // (with the drive's orientation correction of the frame frequency)
        region!(on, bench_begin_flux_slip, bench_end_flux_slip, {
            let s = black_box(&mut *self);
            let mut correction = 0.0;
            if !magnetizing && flux_settled {
                let w = clamp(
                    (ws_prev.abs() - s.orientation_fade_start) * s.orientation_inv_fade_width,
                    0.0,
                    1.0,
                );
                let r_d = rs_hat * s.rs.current_error;
                let signed = if ws_prev >= 0.0 { -r_d } else { r_d };
                correction = clamp(
                    s.orientation_gain_per_flux * w * signed,
                    -s.orientation_limit,
                    s.orientation_limit,
                );
            }
            s.flux.update(
                &s.flux_cfg,
                i.d,
                i.q,
                s.pole_pairs * speed_est + correction,
                magnetizing,
            );
            black_box(&*s);
        });
        let ws = self.flux.stator_frequency;
        let lambda = self.flux.rotor_flux;

        // 6. references
        let (i_sd_ref, i_sq_ref);
        if magnetizing {
            i_sd_ref = self.i_sd_ref;
            i_sq_ref = 0.0;
            self.magnetizing_steps = self.magnetizing_steps.saturating_add(1);
            self.rs_settled_steps = if self.filtered_residual.abs() < self.rs_settled_error {
                self.rs_settled_steps.saturating_add(1)
            } else {
                0
            };
            let rs_done = !self.cfg.rs_estimation
                || self.rs_settled_steps > self.rs_settle_steps
                || self.magnetizing_steps > self.rs_timeout_steps;
            if flux_settled && rs_done {
                self.running = true;
                self.observer.reset(i.q, 0.0, 0.0);
                self.speed_ctl.reset();
            }
        } else {
            let (d, q) = region!(on, bench_begin_speed_pi, bench_end_speed_pi, {
                let s = black_box(&mut *self);
                let dv = clamp(
                    s.speed_target - s.speed_reference,
                    -s.ramp_step,
                    s.ramp_step,
                );
                s.speed_reference += dv;
                let q = s
                    .speed_ctl
                    .update(&s.pi_speed, s.speed_reference - speed_est, 0.0);
                let stalled =
                    s.speed_ctl.saturated() && speed_est.abs() < 0.1 * s.speed_reference.abs();
                s.stall_counter = if stalled { s.stall_counter + 1 } else { 0 };
                if s.stall_counter > s.stall_steps {
                    s.faults_seen += 1;
                }
                black_box((s.i_sd_ref, q))
            });
            i_sd_ref = d;
            i_sq_ref = q;
        }

        // 7. current PIs with decoupling
        let v = region!(on, bench_begin_current_pi, bench_end_current_pi, {
            let s = black_box(&mut *self);
            let v_max = linear_limit(black_box(inp.dc_bus)) * 0.98;
            let ff_d = rs_hat * i_sd_ref + s.referred_rotor_resistance * i_sd_ref
                - lambda * s.inv_rotor_time_constant
                - ws * s.sigma_ls * i_sq_ref;
            let ff_q = (rs_hat + s.referred_rotor_resistance) * i_sq_ref
                + ws * s.sigma_ls * i_sd_ref
                + s.pole_pairs * speed_est * lambda;
            let v_d = s
                .d_ctl
                .update_with_limits(&s.pi_d, i_sd_ref - i.d, ff_d, -v_max, v_max);
            let v_q_max = sqrt(v_max * v_max - v_d * v_d);
            let v_q = s
                .q_ctl
                .update_with_limits(&s.pi_q, i_sq_ref - i.q, ff_q, -v_q_max, v_q_max);
            black_box(Dq { d: v_d, q: v_q })
        });

        // 8. inverse Park at the advanced angle, SVPWM
        let m = region!(on, bench_begin_svpwm, bench_end_svpwm, {
            let lead = ws * ts * self.cfg.delay_periods;
            let rot = small_rotation(black_box(sc), lead);
            let v_ab = inverse_park(v, rot);
            // dead-time sign from the current reference at the advanced angle (drive.rs)
            let i_ref_abc = inverse_clarke(inverse_park(
                Dq {
                    d: i_sd_ref,
                    q: i_sq_ref,
                },
                rot,
            ));
            black_box(modulate(
                &self.pwm_cfg,
                v_ab,
                black_box(inp.dc_bus),
                i_ref_abc,
            ))
        });
        self.applied_voltage = v;
        self.applied_alpha_beta = m.voltage;
        m.duties
    }
}

/// Copy of the drive's private `small_rotation` (drive.rs): sin/cos of theta + delta.
#[inline]
fn small_rotation(sc: SinCosValue, delta: f32) -> SinCosValue {
    let d = clamp(delta, -0.3, 0.3);
    let d2 = d * d;
    let sd = d * (1.0 - d2 * (1.0 / 6.0));
    let cd = 1.0 - d2 * (0.5 - d2 * (1.0 / 24.0));
    SinCosValue {
        sin: sc.sin * cd + sc.cos * sd,
        cos: sc.cos * cd - sc.sin * sd,
    }
}

/// The whole drive step between markers (kept out of line so that its code can be
/// scanned for panics and f64 calls).
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

/// The calibration region: begin immediately followed by end, eight times.
#[inline(never)]
#[no_mangle]
pub fn bench_calibrate() {
    for _ in 0..8 {
        bench_begin_empty();
        bench_end_empty();
    }
}

fn calibrate() {
    bench_calibrate();
}

/// What a run found (printed by the firmware, checked by the host tests).
#[derive(Clone, Copy, Debug, Default)]
pub struct Summary {
    /// Steps run in all.
    pub steps: u32,
    /// Running steps measured.
    pub measured: u32,
    /// Steps where the replica's duties differed (bitwise) from the drive's.
    pub mismatches: u32,
    /// Faults the replica's checks saw.
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
}

/// Runs the scenario: start, magnetise, ramp to [`SPEED_TARGET_RPM`], load step; the
/// regions are measured on [`MEASURED_STEPS`] running steps.
pub fn run() -> Summary {
    let cfg = black_box(bench_config());
    let mut drive = match Drive::new(cfg) {
        Ok(d) => d,
        Err(_) => return Summary::default(),
    };
    let mut shadow = match Shadow::new(cfg, &drive) {
        Some(s) => s,
        None => return Summary::default(),
    };
    let mut plant = Plant::paper_default(1);
    plant.set_substeps(PLANT_SUBSTEPS);
    let target = SPEED_TARGET_RPM * RPM_TO_RAD_S;
    let _ = drive.set_speed_target(target);
    shadow.set_speed_target(target);
    let _ = drive.start();
    // all state escapes: the opaque markers may read and write it
    let drive = black_box(&mut drive);
    let shadow = black_box(&mut shadow);

    calibrate();

    let mut s = Summary::default();
    let mut err_full = 0.0f32;
    let mut err_red = 0.0f32;
    while s.steps < MAX_STEPS && s.measured < MEASURED_STEPS {
        let meas = plant.sample();
        let inp = DriveInputs {
            phase_currents: meas.phase_currents,
            dc_bus: meas.dc_bus,
        };
        let on = drive.state() == DriveState::Running;
        let duties = shadow.step(&inp, on);
        let out = bench_region_drive_step(drive, &inp, on);
        if out.enabled && duties.map(f32::to_bits) != out.duties.map(f32::to_bits) {
            s.mismatches += 1;
        }
        let load = if s.measured >= LOAD_FROM_STEP {
            LoadTorque::Passive {
                torque: LOAD_TORQUE,
            }
        } else {
            LoadTorque::None
        };
        plant.run_period(out.duties, out.enabled, load);
        s.steps += 1;
        if on {
            s.measured += 1;
            let w = plant.speed();
            err_full += (shadow.full_order_speed() - w).abs();
            err_red += (drive.telemetry().speed_estimate - w).abs();
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
    s.replica_faults = shadow.faults_seen;
    s.true_rpm = plant.speed() / RPM_TO_RAD_S;
    s.reduced_rpm = drive.telemetry().speed_estimate / RPM_TO_RAD_S;
    s.full_rpm = shadow.full_order_speed() / RPM_TO_RAD_S;
    s.full_mean_abs_err_rpm = err_full / n / RPM_TO_RAD_S;
    s.reduced_mean_abs_err_rpm = err_red / n / RPM_TO_RAD_S;
    s
}
