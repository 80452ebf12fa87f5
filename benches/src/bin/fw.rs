//! The bench firmware: HAL-free, for `thumbv7em-none-eabihf`, linked with the project's
//! `memory.x`. Runs `scenario::run` (the real drive in closed loop with the motor model,
//! each block bracketed by marker calls) and reports through semihosting, then exits
//! (QEMU quits; `probe-rs run` returns).
//!
//! QEMU path (default features): the markers only write a word; the host runner counts
//! the instructions between them in QEMU's execution log.
//! Board path (feature `dwt`): the markers read DWT CYCCNT and the firmware prints
//! min/mean/max cycles per region (see benches/README.md).
//!
//! On the host this bin is a stub (the scenario itself is tested by the host runner's
//! unit tests).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[path = "../scenario.rs"]
#[allow(dead_code)]
mod scenario;

#[cfg(target_os = "none")]
mod fw {
    use super::scenario;
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hprintln};

    #[entry]
    fn main() -> ! {
        #[cfg(feature = "dwt")]
        {
            // the only peripheral touched: the core's trace/cycle counter (no clocks set
            // up: the G474 runs from HSI16 with zero flash wait states)
            if let Some(mut p) = cortex_m::Peripherals::take() {
                p.DCB.enable_trace();
                p.DWT.set_cycle_count(0);
                p.DWT.enable_cycle_counter();
            }
        }
        let s = scenario::run();
        hprintln!(
            "ACIM-BENCH summary steps={} measured={} mismatches={} replica_faults={} drive_faulted={} true_rpm={} reduced_rpm={} full_rpm={} reduced_err_rpm={} full_err_rpm={} two_rate_measured={} two_rate_faulted={} loaded_measured={} loaded_true_rpm={} two_rate_loaded_measured={}",
            s.steps,
            s.measured,
            s.mismatches,
            s.replica_faults,
            s.drive_faulted as u8,
            s.true_rpm,
            s.reduced_rpm,
            s.full_rpm,
            s.reduced_mean_abs_err_rpm,
            s.full_mean_abs_err_rpm,
            s.two_rate_measured,
            s.two_rate_faulted as u8,
            s.loaded_measured,
            s.loaded_true_rpm,
            s.two_rate_loaded_measured
        );
        #[cfg(feature = "dwt")]
        report_dwt();
        debug::exit(debug::EXIT_SUCCESS);
        loop {
            cortex_m::asm::bkpt();
        }
    }

    #[cfg(feature = "dwt")]
    fn report_dwt() {
        let stats = cortex_m::interrupt::free(|cs| *scenario::dwt::STATS.borrow(cs).borrow());
        // marker overhead: the empty region's minimum
        let base = stats[0].min;
        hprintln!("ACIM-BENCH dwt overhead={} (subtracted)", base);
        for (name, st) in scenario::REGIONS.iter().zip(stats.iter()) {
            if st.n == 0 {
                continue;
            }
            let mean = st.sum / st.n as u64;
            hprintln!(
                "ACIM-BENCH dwt region={} n={} min={} mean={} max={}",
                name,
                st.n,
                st.min.saturating_sub(base),
                (mean as u32).saturating_sub(base),
                st.max.saturating_sub(base)
            );
        }
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo) -> ! {
        hprintln!("ACIM-BENCH panic");
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::bkpt();
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "acim-bench-fw is the Cortex-M4F bench firmware: build it with \
         --target thumbv7em-none-eabihf, or run `cargo run -p acim-bench --release`"
    );
    std::process::exit(2);
}
