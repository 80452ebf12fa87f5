//! One case of the robustness matrix (development aid):
//! `cargo run --release -p acim-sim --example robust_case -- <variant 0..10> <rpm> <motor|regen> <load> <standstill|running>`
use acim_sim::robustness::{Case, Variant};
use acim_sim::scenario::RsMode;

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let all = [
        Variant::Nominal,
        Variant::ControllerRsPlus20,
        Variant::ControllerRsMinus20,
        Variant::PlantRsDrift30,
        Variant::PlantRsStep20,
        Variant::DeadTime1_0,
        Variant::DeadTime2_2,
        Variant::Offset20mA,
        Variant::DeadTime1_0NotIdentified,
        Variant::DeadTime2_2NotIdentified,
        Variant::OffsetDrift20mA,
    ];
    let case = Case {
        variant: all[a[0].parse::<usize>().unwrap()],
        rpm: a[1].parse().unwrap(),
        regenerating: a[2] == "regen",
        load_nm: a[3].parse().unwrap(),
    };
    let mode = if a[4] == "running" {
        RsMode::Running
    } else {
        RsMode::Standstill
    };
    let t = std::time::Instant::now();
    let mut sc = case.scenario(mode);
    if a[4] == "off" {
        sc.drive.estimation.rs_estimation = false;
    }
    for kv in a.iter().skip(5) {
        sc = sc.with_overrides(std::slice::from_ref(kv)).unwrap();
    }
    let o = acim_sim::robustness::run_scenario(&case, &sc).unwrap();
    let r = acim_sim::sim::run(&sc).unwrap();
    eprintln!("current gain correction {:.5}", r.current_gain_correction);
    eprintln!("inverter {:?}", r.inverter_test);
    if let Ok(p) = std::env::var("CSV") {
        let mut f = String::from(acim_sim::sim::CSV_HEADER);
        f.push('\n');
        for (i, row) in r.rows.iter().enumerate() {
            if i % std::env::var("CSV_EVERY").map_or(50, |v| v.parse().unwrap()) == 0 {
                f.push_str(&row.csv());
                f.push('\n');
            }
        }
        std::fs::write(p, f).unwrap();
    }
    println!("{}", acim_sim::robustness::table(&[o]));
    eprintln!("{:.1} s", t.elapsed().as_secs_f64());
}
