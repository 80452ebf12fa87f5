//! Real-time factor of the simulator: simulated seconds per wall-clock second for the
//! 10 s paper scenarios (closed loop, averaged inverter, 5 RK4 sub-steps per period,
//! 12-bit noisy sensors), one core. The target is 100x.
//!
//! `cargo bench -p acim-sim` (a plain harness: median of repeated runs; the figure is a
//! throughput, so a statistics framework would add little).

use std::time::Instant;

fn main() {
    let runs = 7;
    let mut worst_median = f64::INFINITY;
    println!(
        "{:<18} {:>10} {:>10} {:>10}",
        "scenario", "median s", "min s", "x realtime"
    );
    for name in ["paper-fig7", "paper-fig10", "paper-fig12"] {
        let sc = acim_sim::builtins::get(name).expect("built-in");
        let mut times = Vec::with_capacity(runs);
        for _ in 0..runs {
            let t0 = Instant::now();
            let r = acim_sim::sim::run(&sc).expect("valid");
            std::hint::black_box(&r);
            times.push(t0.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        let median = times[runs / 2];
        let rtf = sc.duration_s as f64 / median;
        worst_median = worst_median.min(rtf);
        println!("{name:<18} {median:>10.4} {:>10.4} {rtf:>10.0}", times[0]);
    }
    println!("slowest median real-time factor: {worst_median:.0}x (target >= 100x)");
}
