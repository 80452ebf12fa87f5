//! The linearised model against the sampled closed loop at the points docs/robustness.md
//! quotes: `cargo run --release -p acim-sim --example model_vs_loop`.
//!
//! - the paper's scheme (orientation gain 0) regenerating at 250 rpm / -1.5 N m: the
//!   model's eigenvalue, the two-state analysis, the sampled loop's growth while the
//!   error is small (`stability::linear_growth_rate`) and the maps' figure
//!   (`stability::measure`), at 5, 10 and 20 kHz and three current-loop bandwidths;
//! - the far side, 60 rpm / -4.5 N m regenerating, at orientation gains 2 and 1.
use acim_sim::linear::{base_scenario, linearise};
use acim_sim::scenario::Scenario;
use acim_sim::stability::{linear_growth_rate, measure_with, theory};

/// A scenario change and its label.
type Variant = (&'static str, fn(&mut Scenario));

fn main() {
    let variants: [Variant; 5] = [
        ("5 kHz, default bandwidth", |_| {}),
        ("10 kHz", |s| s.drive.loops.control_period_s = 1.0e-4),
        ("20 kHz", |s| s.drive.loops.control_period_s = 5.0e-5),
        ("current bandwidth 500 rad/s", |s| {
            s.drive.loops.current_bandwidth_rad_s = 500.0
        }),
        ("current bandwidth 2000 rad/s", |s| {
            s.drive.loops.current_bandwidth_rad_s = 2000.0
        }),
    ];
    println!(
        "paper scheme (k = 0), 250 rpm, -1.5 N m: theory {:+.2}/s",
        theory(250.0, -1.5, 0.0)
    );
    println!(
        "| variant | model (1/s) | sampled, small error (1/s) | sampled, maps' measure (1/s) |"
    );
    println!("|---|---|---|---|");
    for (name, setup) in variants {
        let mut sc = base_scenario();
        setup(&mut sc);
        sc.drive.estimation.orientation_gain = 0.0;
        let model = linearise(&sc, 250.0, -1.5)
            .expect("valid scenario")
            .map_or(f64::NAN, |l| l.max_real());
        let small = linear_growth_rate(250.0, -1.5, 0.0, &setup).expect("valid scenario");
        let map = measure_with(250.0, -1.5, 0.0, &setup).expect("valid scenario");
        println!(
            "| {name} | {model:+.2} | {small:+.2} | {:+.2} |",
            map.growth_rate
        );
    }
    println!();
    println!("far side, 60 rpm, -4.5 N m (Rs held, no regeneration limit)");
    println!("| orientation gain | model | sampled, maps' measure (1/s) |");
    println!("|---|---|---|");
    for k in [2.0f32, 1.0] {
        let mut sc = base_scenario();
        sc.drive.estimation.orientation_gain = k;
        let l = linearise(&sc, 60.0, -4.5).expect("valid scenario");
        let model = l.map_or("no equilibrium".into(), |l| {
            let (re, im) = l.eigenvalues[0];
            format!("{re:+.2} +/- {:.1}j", im.abs())
        });
        let map = measure_with(60.0, -4.5, k, &|_| {}).expect("valid scenario");
        println!("| {k} | {model} | {:+.2} |", map.growth_rate);
    }
}
