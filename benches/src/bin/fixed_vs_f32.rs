//! Instruction counts of the fixed-point path next to the f32 path on the same core:
//! Cortex-M3 (`thumbv7m-none-eabi`, f32 in software) on QEMU's `netduino2` (STM32F205) and
//! Cortex-M4F (`thumbv7em-none-eabihf`, hardware f32) on `netduinoplus2` (STM32F405).
//!
//! Counting: QEMU runs with `-icount shift=4` (the virtual clock advances exactly 16 ns
//! per executed instruction) and the firmware reads the SysTick counter (core clock)
//! around each region; a block of 1000 `nop`s calibrates ticks per instruction and the
//! empty region the read overhead, so the figures are executed instructions (not
//! cycles; the f32 soft-float routines of the M3 are included in its counts).
//!
//! The loop: both drives (project defaults, Rs estimator on in the standstill mode: see
//! `config`) run the same synthetic
//! "ideal current loop" (each step's measured currents are the previous step's
//! references at the next sampling angle, plus a little deterministic noise), which
//! exercises the whole running path without the motor model (its soft-float RK4 would
//! dominate the M3 run). Each drive magnetises, then 500 running steps are measured: on
//! even steps the whole `step`, on odd steps the regions of `step_probed`; the observer
//! alone is measured on each arithmetic's own inputs every step.
//!
//! Markers: the fixed-point regions are also bracketed by calls to `#[inline(never)]
//! #[no_mangle]` functions `bench_begin_fx_R` / `bench_end_fx_R` (distinct bodies), so
//! the host runner (`cargo run -p acim-bench --release`) counts the executed
//! instructions between them exactly in QEMU's execution log and weights them with the
//! Cortex-M4 or Cortex-M3 timing table (the gate of the fixed path). The marker calls sit
//! inside the SysTick window too; the `empty` region calibrates both away.
//!
//! Run (from the workspace root):
//!
//! ```sh
//! cargo build -p acim-bench --profile firmware --target thumbv7m-none-eabi --bin acim-bench-fixed
//! qemu-system-arm -machine netduino2 -cpu cortex-m3 -nographic -monitor none -serial none \
//!   -semihosting-config enable=on,target=native -icount shift=4 \
//!   -kernel $CARGO_TARGET_DIR/thumbv7m-none-eabi/firmware/acim-bench-fixed
//! ```
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod fw {
    use acim::drive::{
        Drive, DriveConfig, DriveInputs, DriveState, NoProbe, StepProbe, StepRegion,
    };
    use acim::fixed::{FixedDrive, FixedInputs, PerUnitBases, Q24};
    use acim::frames::{inverse_clarke, inverse_park, Dq, FastSinCos};
    use acim::observer::ObserverCoeffs;
    use acim::observer::{ObserverInputs, ReducedOrderObserver};
    use core::hint::black_box;
    use cortex_m::peripheral::{syst::SystClkSource, SYST};
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hprintln};

    const REGIONS: [&str; 12] = [
        "empty",
        "fault_checks",
        "clarke_park",
        "observer_reduced",
        "rs_estimator",
        "flux_slip",
        "speed_pi",
        "current_pi",
        "svpwm",
        "drive_step",
        "observer_alone",
        "fast_step",
    ];
    const MEASURED: u32 = 500;

    macro_rules! markers {
        ($($id:literal $begin:ident $end:ident),* $(,)?) => {
            $(
                // no_mangle: the host runner finds the marker by its symbol
                #[allow(unsafe_code)]
                #[inline(never)]
                #[no_mangle]
                pub extern "C" fn $begin() {
                    black_box($id as u32);
                }
                #[allow(unsafe_code)]
                #[inline(never)]
                #[no_mangle]
                pub extern "C" fn $end() {
                    black_box($id as u32 + 100);
                }
            )*
            /// The begin marker of region `id` (constant at every call site once inlined).
            #[inline(always)]
            fn marker_begin(id: usize) {
                match id {
                    $($id => $begin(),)*
                    _ => {}
                }
            }
            /// The end marker of region `id`.
            #[inline(always)]
            fn marker_end(id: usize) {
                match id {
                    $($id => $end(),)*
                    _ => {}
                }
            }
        };
    }

    // ids are the indices in REGIONS
    markers!(
        // the bodies pass distinct ids through black_box: never merged, never removed
        0 bench_begin_fx_empty bench_end_fx_empty,
        1 bench_begin_fx_fault_checks bench_end_fx_fault_checks,
        2 bench_begin_fx_clarke_park bench_end_fx_clarke_park,
        3 bench_begin_fx_observer_reduced bench_end_fx_observer_reduced,
        4 bench_begin_fx_rs_estimator bench_end_fx_rs_estimator,
        5 bench_begin_fx_flux_slip bench_end_fx_flux_slip,
        6 bench_begin_fx_speed_pi bench_end_fx_speed_pi,
        7 bench_begin_fx_current_pi bench_end_fx_current_pi,
        8 bench_begin_fx_svpwm bench_end_fx_svpwm,
        9 bench_begin_fx_drive_step bench_end_fx_drive_step,
        10 bench_begin_fx_observer_alone bench_end_fx_observer_alone,
        11 bench_begin_fx_fast_step bench_end_fx_fast_step,
    );

    #[derive(Clone, Copy)]
    struct Stat {
        min: u32,
        max: u32,
        sum: u64,
        n: u32,
    }
    const NEW: Stat = Stat {
        min: u32::MAX,
        max: 0,
        sum: 0,
        n: 0,
    };

    struct Stats {
        s: [Stat; REGIONS.len()],
        t0: u32,
        /// Whether this arithmetic's regions call the trace markers (the fixed point).
        traced: bool,
    }

    impl Stats {
        #[inline(always)]
        fn begin(&mut self, id: usize) {
            if self.traced {
                marker_begin(id);
            }
            self.t0 = SYST::get_current();
        }
        #[inline(always)]
        fn end(&mut self, id: usize) {
            let t1 = SYST::get_current();
            if self.traced {
                marker_end(id);
            }
            let d = self.t0.wrapping_sub(t1) & 0x00FF_FFFF; // counts down
            if let Some(st) = self.s.get_mut(id) {
                st.min = st.min.min(d);
                st.max = st.max.max(d);
                st.sum += d as u64;
                st.n += 1;
            }
        }
    }

    fn id(r: StepRegion) -> usize {
        match r {
            StepRegion::FaultChecks => 1,
            StepRegion::ClarkePark => 2,
            StepRegion::ObserverReduced => 3,
            StepRegion::RsEstimator => 4,
            StepRegion::FluxSlip => 5,
            StepRegion::SpeedPi => 6,
            StepRegion::CurrentPi => 7,
            StepRegion::Svpwm => 8,
        }
    }

    impl StepProbe for Stats {
        #[inline(always)]
        fn begin(&mut self, r: StepRegion) {
            Stats::begin(self, id(r));
        }
        #[inline(always)]
        fn end(&mut self, r: StepRegion) {
            Stats::end(self, id(r));
        }
    }

    /// Deterministic noise in [-1, 1).
    fn noise(seed: &mut u32) -> f32 {
        *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (*seed >> 8) as f32 * (2.0 / 16_777_216.0) - 1.0
    }

    /// Phase currents of dq current `i` at `angle` (rad), plus noise (A).
    fn currents(i: Dq, angle: f32, seed: &mut u32) -> [f32; 3] {
        let [a, b, c] = inverse_clarke(inverse_park(i, FastSinCos::eval(angle)));
        [a + 0.01 * noise(seed), b + 0.01 * noise(seed), c]
    }

    #[inline(never)]
    fn calibrate(stats: &mut Stats) -> (u32, u32) {
        let mut empty = u32::MAX;
        let mut nops = u32::MAX;
        for _ in 0..8 {
            stats.begin(0);
            let t1 = SYST::get_current();
            if stats.traced {
                marker_end(0);
            }
            empty = empty.min(stats.t0.wrapping_sub(t1) & 0x00FF_FFFF);
            stats.begin(11);
            // SAFETY: 1000 `nop`s: no memory, register or flag effects. Not declared
            // `nomem`: the asm then orders with the volatile SysTick reads around it (with
            // `nomem` the compiler may hoist the closing read above the nops).
            #[allow(unsafe_code)]
            unsafe {
                core::arch::asm!(".rept 1000", "nop", ".endr", options(nostack))
            };
            let t1 = SYST::get_current();
            nops = nops.min(stats.t0.wrapping_sub(t1) & 0x00FF_FFFF);
        }
        (empty, nops)
    }

    fn report(name: &str, stats: &Stats, empty: u32, nops: u32) {
        // ticks per instruction = (nops - empty) / 1000
        let per = (nops.saturating_sub(empty)) as f32 / 1000.0;
        hprintln!(
            "ACIM-FIXED arithmetic={} ticks_per_insn={} overhead_ticks={}",
            name,
            per,
            empty
        );
        for (r, st) in REGIONS.iter().zip(stats.s.iter()).skip(1) {
            if st.n == 0 {
                continue;
            }
            let conv = |t: u32| ((t.saturating_sub(empty)) as f32 / per + 0.5) as u32;
            let mean = (st.sum / st.n as u64) as u32;
            hprintln!(
                "ACIM-FIXED arithmetic={} region={} n={} insn_min={} insn_mean={} insn_max={}",
                name,
                r,
                st.n,
                conv(st.min),
                conv(mean),
                conv(st.max)
            );
        }
    }

    fn config() -> DriveConfig {
        let mut c = DriveConfig::paper_defaults();
        c.estimation.rs_estimation = true;
        // the synthetic loop has no machine behind the voltages: the running Rs law
        // (the default) reads them as a resistance and took the estimate
        // to its bound (EstimatorOutOfRange) within 1.4 s in both arithmetics, so this
        // comparison keeps the standstill mode (the running law's Q7.24 cost is not in
        // these figures; the f32 bench, closed loop against the motor model, has it)
        c.estimation.rs_estimation_mode = acim::RsEstimationMode::Standstill;
        // nor does the current-sensor gain calibration have one: its q-axis voltage is
        // the current PI's response to the noise alone (a random walk), which it read as
        // a mismatch at its 5 % bound, and the two drives then faulted; off here (it runs
        // only while magnetizing, outside these figures; its two products per step in
        // the sense stage remain)
        c.start.current_gain_calibration = false;
        // nor the inverter test at start (on by default): its fit would
        // read the current PI's voltage, and its 0.6 s before speed control moved the
        // measured steps into the speed ramp (drive_step 2617 -> 2623-2689 instructions
        // on the M4F, the speed PI 310 -> 323-384); off, the figures stay those of the
        // same steady running steps
        c.start.inverter_identification = false;
        c
    }

    // The measured fixed-point work, out of line: the host runner's trace filter covers
    // these functions (and what they call) only.
    #[inline(never)]
    fn fixed_step(d: &mut FixedDrive, inp: &FixedInputs, st: &mut Stats) {
        st.begin(9);
        black_box(d.step(black_box(inp)));
        st.end(9);
    }

    /// A control period between slow ticks: the fast path alone (`Drive::step_fast`).
    #[inline(never)]
    fn fixed_step_fast(d: &mut FixedDrive, inp: &FixedInputs, st: &mut Stats) {
        st.begin(11);
        black_box(d.step_fast(black_box(inp)));
        st.end(11);
    }

    #[inline(never)]
    fn fixed_step_probed(d: &mut FixedDrive, inp: &FixedInputs, st: &mut Stats) {
        black_box(d.step_probed(black_box(inp), st));
    }

    #[inline(never)]
    fn fixed_observer(
        o: &mut ReducedOrderObserver<Q24>,
        c: &ObserverCoeffs<Q24>,
        u: &ObserverInputs<Q24>,
        st: &mut Stats,
    ) {
        st.begin(10);
        o.update(black_box(c), black_box(u));
        st.end(10);
        black_box(&*o);
    }

    #[entry]
    fn main() -> ! {
        let Some(mut p) = cortex_m::Peripherals::take() else {
            debug::exit(debug::EXIT_FAILURE);
            loop {}
        };
        p.SYST.set_clock_source(SystClkSource::Core);
        p.SYST.set_reload(0x00FF_FFFF);
        p.SYST.clear_current();
        p.SYST.enable_counter();
        let cfg = config();
        let ts = cfg.loops.control_period;
        let bases = PerUnitBases::PAPER;
        let (Ok(mut f32_drive), Ok(mut fixed_drive)) =
            (Drive::new(cfg), FixedDrive::with_bases(cfg, bases))
        else {
            hprintln!("ACIM-FIXED config rejected");
            debug::exit(debug::EXIT_FAILURE);
            loop {}
        };
        let obs_cfg = *f32_drive.observer_config();
        let obs_fixed_cfg = obs_cfg.convert::<acim::fixed::Q24>(&bases);
        let mut st32 = Stats {
            s: [NEW; REGIONS.len()],
            t0: 0,
            traced: false,
        };
        let mut stq = Stats {
            s: [NEW; REGIONS.len()],
            t0: 0,
            traced: true,
        };
        let (empty, nops) = calibrate(&mut st32);
        // the trace markers' calibration (the SysTick figures use the untraced one)
        let _ = calibrate(&mut stq);
        let _ = f32_drive.set_speed_target(500.0 * acim::math::RPM_TO_RAD_S);
        let _ = fixed_drive.set_speed_target_si(500.0 * acim::math::RPM_TO_RAD_S);
        // powered first (switches off, zero current: the synthetic loop has no sensor
        // offsets) for the offset measurement every start waits for, so the start below
        // switches at once. The noise is not drawn here: the synthetic loop has no machine
        // behind its voltages, and the standstill Rs identification it then runs ends at
        // its bound (EstimatorOutOfRange) for some noise sequences; this one is the
        // sequence the figures were measured with.
        let idle32 = DriveInputs {
            phase_currents: [0.0; 3],
            dc_bus: 325.0,
        };
        let idleq = FixedInputs {
            phase_currents: [Q24(0); 3],
            dc_bus: Q24::from_pu(325.0 / bases.voltage),
        };
        for _ in 0..f32_drive.coeffs().limits.offset_settle_steps {
            f32_drive.step(&idle32);
            fixed_drive.step(&idleq);
        }
        let _ = f32_drive.start();
        let _ = fixed_drive.start();
        let mut seed = 12345u32;
        let (mut i32_next, mut iq_next) = ([1.5f32, -0.75, -0.75], [1.5f32, -0.75, -0.75]);
        let mut obs32 = ReducedOrderObserver::new();
        let mut obsq = ReducedOrderObserver::<Q24>::new();
        let (mut measured, mut steps, mut faults) = (0u32, 0u32, 0u32);
        while measured < MEASURED && steps < 20_000 {
            steps += 1;
            let running = f32_drive.state() == DriveState::Running
                && fixed_drive.state() == DriveState::Running;
            let inp32 = DriveInputs {
                phase_currents: i32_next,
                dc_bus: 325.0,
            };
            let k = 1.0 / bases.current;
            let inpq = FixedInputs {
                phase_currents: [
                    Q24::from_pu(iq_next[0] * k),
                    Q24::from_pu(iq_next[1] * k),
                    Q24::from_pu(iq_next[2] * k),
                ],
                dc_bus: Q24::from_pu(325.0 / bases.voltage),
            };
            if running && steps % 2 == 0 {
                st32.begin(9);
                black_box(f32_drive.step(black_box(&inp32)));
                st32.end(9);
                // the whole step (a tick's slow work inline) every fourth period and at every
                // slow tick, the fast path alone (`fast_step`) on the others
                if steps % 4 == 0 || fixed_drive.slow_tick_due() {
                    fixed_step(&mut fixed_drive, &inpq, &mut stq);
                } else {
                    fixed_step_fast(&mut fixed_drive, &inpq, &mut stq);
                }
            } else if running {
                black_box(f32_drive.step_probed(black_box(&inp32), &mut st32));
                fixed_step_probed(&mut fixed_drive, &inpq, &mut stq);
            } else {
                f32_drive.step(&inp32);
                fixed_drive.step(&inpq);
            }
            if running {
                measured += 1;
                // the observer alone, on the drive's own operating point
                let t = *f32_drive.telemetry();
                let u = ObserverInputs {
                    i_sq: t.current.q,
                    i_sd: t.current.d,
                    stator_frequency: t.stator_frequency,
                    v_sq: t.voltage.q,
                    rotor_flux: t.rotor_flux,
                    inv_rotor_flux: 1.0 / t.rotor_flux.max(0.05),
                    equivalent_resistance: t.stator_resistance_estimate + 7.81,
                    far_side_error: 0.0,
                };
                st32.begin(10);
                obs32.update(black_box(&obs_cfg.coeffs), black_box(&u));
                st32.end(10);
                black_box(&obs32);
                if let Some(c) = obs_fixed_cfg.as_ref() {
                    let q = fixed_drive.telemetry();
                    let uq = ObserverInputs {
                        i_sq: q.current.q,
                        i_sd: q.current.d,
                        stator_frequency: q.stator_frequency,
                        v_sq: q.voltage.q,
                        rotor_flux: q.rotor_flux,
                        inv_rotor_flux: Q24(acim::fixed::q::reciprocal(q.rotor_flux.0)),
                        equivalent_resistance: q.stator_resistance_estimate + Q24(3_276_000),
                        far_side_error: Q24(0),
                    };
                    fixed_observer(&mut obsq, c, &uq, &mut stq);
                }
            }
            // ideal current loop: next samples = this step's references at the next angle
            let t = f32_drive.telemetry();
            i32_next = currents(
                t.current_reference,
                t.angle + t.stator_frequency * ts,
                &mut seed,
            );
            let t = fixed_drive.telemetry_si();
            iq_next = currents(
                t.current_reference,
                t.angle + t.stator_frequency * ts,
                &mut seed,
            );
            for d in [&mut f32_drive] {
                if d.state() == DriveState::Fault {
                    hprintln!("ACIM-FIXED f32 fault at step {}: {:?}", steps, d.fault());
                    faults += 1;
                    let _ = d.reset_fault();
                    let _ = d.start();
                }
            }
            if fixed_drive.state() == DriveState::Fault {
                hprintln!(
                    "ACIM-FIXED fixed fault at step {}: {:?}",
                    steps,
                    fixed_drive.fault()
                );
                faults += 1;
                let _ = fixed_drive.reset_fault();
                let _ = fixed_drive.start();
            }
        }
        let _ = NoProbe;
        hprintln!(
            "ACIM-FIXED summary steps={} measured={} faults={} f32_rpm={} fixed_rpm={}",
            steps,
            measured,
            faults,
            f32_drive.telemetry().speed_estimate * acim::math::RAD_S_TO_RPM,
            fixed_drive.telemetry_si().speed_estimate * acim::math::RAD_S_TO_RPM
        );
        report("f32", &st32, empty, nops);
        report("fixed", &stq, empty, nops);
        debug::exit(debug::EXIT_SUCCESS);
        loop {
            cortex_m::asm::bkpt();
        }
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo) -> ! {
        hprintln!("ACIM-FIXED panic");
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::bkpt();
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "acim-bench-fixed is Cortex-M firmware: build it with --target thumbv7m-none-eabi \
         (or thumbv7em-none-eabihf) and run it in QEMU (see the file's docs)"
    );
    std::process::exit(2);
}
