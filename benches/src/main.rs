//! Host-side runner of the cycle-count bench.
//!
//! ```text
//! cargo run -p acim-bench --release                  # measure, print, write results/
//! cargo run -p acim-bench --release -- --check       # also fail on budget/panic/f64
//! cargo run -p acim-bench --release -- --update-budget
//! cargo run -p acim-bench --release -- --weigh-isr ELF DIR [--check|--update-budget]
//! ```
//!
//! Steps: builds the firmware bin `acim-bench-fw` for `thumbv7em-none-eabihf` (the `firmware` profile, as the drive's firmware),
//! disassembles it with the rustup `llvm-tools` `llvm-objdump`, finds the marker functions
//! and the static call graph of the measured code, runs QEMU (`netduinoplus2`, Cortex-M4F)
//! with one guest instruction per translation block and the execution log restricted by
//! `-dfilter` to the measured code (less the soft-float routines, which only unmeasured
//! code calls: [`TraceFilter`]), and stream-parses the log from a pipe (never held in
//! memory; read in batches, [`BatchedPipe`]): every executed instruction is one `Trace`
//! line with its PC, so the count between the `bench_begin_R` and `bench_end_R` marker
//! calls is exact. Each executed instruction is weighted with the Cortex-M4 timing table
//! below and the pipeline model of [`timed`] to estimate cycles (decoded once per static
//! instruction: [`Weights`]). The same run traces the fixed-point firmware
//! `acim-bench-fixed` on the Cortex-M4F and the Cortex-M3 (`netduino2`; [`Core::M3`] for
//! its multiplies), in two more threads beside the f32 run, and `--weigh-isr` weighs the
//! firmware-in-the-loop traces of the control interrupt.
//!
//! ## Cortex-M4 timing table (Arm Cortex-M4 TRM r0p1, tables 3-1 and 7-1) and assumptions
//!
//! | instructions | cycles |
//! |---|---|
//! | ALU, MOV/MOVW/MOVT, CMP/TST, shifts, extend, bitfield, IT, NOP, MUL, SMULL/UMULL/SMLAL/UMLAL | 1 |
//! | MLA, MLS | 2 |
//! | SDIV, UDIV | 12 (the TRM's 2-12 is data dependent; worst case taken) |
//! | LDR/LDRB/LDRH/LDRSB/LDRSH, STR/STRB/STRH | 2, 1 directly after a single load/store in the table-only figure (the TRM's exact pipelining rules: [`timed`]) |
//! | LDRD, STRD | 3 |
//! | LDM/STM/PUSH/POP (N registers) | 1 + N; POP/LDM with PC: 1 + N + 2 |
//! | B, B`<cond>`, CBZ/CBNZ | taken 3 (1 + 2 refill), not taken 1 |
//! | BL, BX, BLX | 3 |
//! | TBB, TBH | 4 |
//! | other writes of PC (MOV/ADD/LDR pc) | + 2 |
//! | VADD/VSUB/VMUL/VNMUL/VABS/VNEG/VCMP/VCVT/VMRS/VMSR (F32), VMOV between S registers | 1 |
//! | VMOV one or two core registers <-> S / D registers | 2 (one float: in [`timed`]) |
//! | VLDR, VSTR | 2 |
//! | VLDM/VSTM/VPUSH/VPOP (N single registers, a D counts 2) | 1 + N |
//! | VMLA/VMLS/VNMLA/VNMLS, VFMA/VFMS/VFNMA/VFNMS | 3 |
//! | VDIV, VSQRT | 14 |
//!
//! On top of the table, [`timed`] models the TRM's load/store pipelining rules, the FP
//! result-use stall and the core-FP moves (validated in the tests on the TRM's
//! own sequences), and [`slack`] reports what stays open (refill 1-3 cycles, division
//! overlap, M3 early termination) as a range.
//!
//! Assumptions: zero-wait-state memory (code in CCM SRAM or flash hidden by the ART
//! accelerator), no bus contention, no interrupts; no modelling of the FPU's load/store
//! pipelining with core loads or of IT folding (IT counted as 1). An instruction skipped
//! inside an IT block is counted as executed (1 cycle), as the core does. QEMU itself is
//! not cycle-accurate: only the instruction counts are exact.
//!
//! Region overhead: the `bl bench_end_R` call is inside the region; the minimum of the
//! `empty` calibration region (begin immediately followed by end) is subtracted from every
//! sample (instructions and cycles).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

#[path = "scenario.rs"]
#[allow(dead_code)]
mod scenario;

const TARGET: &str = "thumbv7em-none-eabihf";
const FW_BIN: &str = "acim-bench-fw";
/// Budget tolerance: a region fails when its max instruction count exceeds the budget
/// by more than this fraction.
const BUDGET_TOLERANCE: f64 = 0.05;
const CLOCK_MHZ: f64 = 170.0;

/// The regions of the JSON report (marker regions, without the calibration one), in the
/// order of the step.
const REPORT_REGIONS: [&str; 20] = [
    "sincos",
    "clarke_park",
    "current_pi",
    "speed_pi",
    "flux_slip",
    "observer_reduced",
    "observer_full_order",
    "observer_flux",
    "rs_estimator",
    "svpwm",
    "fault_checks",
    "drive_step",
    "overmodulation",
    "two_rate_fast",
    "two_rate_tick",
    "two_rate_slow",
    "drive_step_loaded",
    "two_rate_fast_loaded",
    "two_rate_tick_loaded",
    "two_rate_slow_loaded",
];

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut check = false;
    let mut update_budget = false;
    let mut keep_trace: Option<PathBuf> = None;
    let mut allow_panic_paths = false;
    let mut weigh_isr: Option<(PathBuf, PathBuf)> = None;
    let mut profile_region: &'static str = "drive_step";
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--check" => check = true,
            "--update-budget" => update_budget = true,
            "--allow-panic-paths" => allow_panic_paths = true,
            "--help" | "-h" => {
                println!(
                    "acim-bench [--check] [--update-budget]\n  --check          fail (exit 1) when a region's max instruction count exceeds\n                   benches/budget.json by more than 5 %, or the drive step calls a\n                   panic or f64 routine, or the probed step diverged from the real one\n  --update-budget  write the measured max instruction counts to benches/budget.json\n  --allow-panic-paths  report panic/f64 paths in the drive step without failing\n  --profile REGION     keep the per-instruction profile of REGION (default drive_step)\n                   in results/profile_REGION.txt\n  --keep-trace FILE    also write the (filtered) QEMU execution log to FILE\n  --weigh-isr ELF DIR  weigh the firmware-in-the-loop traces DIR/fil-isr-trace-<phase>.txt\n                   (executed addresses of the control interrupt of ELF) with the\n                   Cortex-M4 model; with --check hold them to firmware/fil/isr-budget.json,\n                   with --update-budget write the measured maxima there"
                );
                return;
            }
            "--profile" => {
                i += 1;
                let Some(name) = args
                    .get(i)
                    .and_then(|r| REPORT_REGIONS.iter().find(|x| **x == r.as_str()))
                else {
                    eprintln!(
                        "--profile needs one of the regions: {}",
                        REPORT_REGIONS.join(", ")
                    );
                    std::process::exit(2);
                };
                profile_region = name;
            }
            "--keep-trace" => {
                i += 1;
                keep_trace = args.get(i).map(PathBuf::from);
            }
            "--weigh-isr" => {
                let (Some(elf), Some(dir)) = (args.get(i + 1), args.get(i + 2)) else {
                    eprintln!("--weigh-isr needs ELF and DIR (see --help)");
                    std::process::exit(2);
                };
                weigh_isr = Some((PathBuf::from(elf), PathBuf::from(dir)));
                i += 2;
            }
            other => {
                eprintln!("unknown argument {other} (see --help)");
                std::process::exit(2);
            }
        }
        i += 1;
    }
    let result = match weigh_isr {
        Some((elf, dir)) => weigh_isr_traces(&elf, &dir, check, update_budget),
        None => run(
            check,
            update_budget,
            allow_panic_paths,
            keep_trace,
            profile_region,
        ),
    };
    match result {
        Ok(true) => {}
        Ok(false) => {
            eprintln!("acim-bench: CHECK FAILED");
            std::process::exit(1);
        }
        Err(e) => {
            eprintln!("acim-bench: error: {e}");
            std::process::exit(2);
        }
    }
}

type Res<T> = Result<T, String>;

fn bench_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn run(
    check: bool,
    update_budget: bool,
    allow_panic_paths: bool,
    keep_trace: Option<PathBuf>,
    profile_region: &'static str,
) -> Res<bool> {
    let t0 = Instant::now();
    let elf = build_firmware()?;
    let t_build = t0.elapsed();
    let tools = llvm_tools()?;
    let dis = Disassembly::load(&tools, &elf)?;
    let markers = dis.markers("", &scenario::REGIONS)?;

    // static call graphs: the whole measured code (for -dfilter), and the drive step alone
    // (for the panic/f64 scan)
    let shadow_root = dis
        .function_named(|n| n == "bench_regions_step")
        .ok_or("cannot find bench_regions_step in the disassembly")?;
    let drive_root = dis
        .function_named(|n| n == "bench_region_drive_step")
        .ok_or("cannot find bench_region_drive_step")?;
    let two_rate_root = dis
        .function_named(|n| n == "bench_region_two_rates")
        .ok_or("cannot find bench_region_two_rates")?;
    let step_graph = dis.reachable(&[drive_root]);
    let calib_root = dis
        .function_named(|n| n == "bench_calibrate")
        .ok_or("cannot find bench_calibrate")?;
    // the same steps at the steady loaded point
    let loaded_roots = [
        "bench_region_drive_step_loaded",
        "bench_region_two_rates_loaded",
    ]
    .iter()
    .map(|r| {
        dis.function_named(|n| n == *r)
            .ok_or(format!("cannot find {r}"))
    })
    .collect::<Res<Vec<_>>>()?;
    let mut roots = vec![shadow_root, drive_root, two_rate_root, calib_root];
    roots.extend(loaded_roots);
    roots.extend(markers.values().map(|m| m.func));
    let measured_graph = dis.reachable(&roots);

    let qemu = Qemu::detect()?;
    // The three traced runs (f32 on the M4F; the fixed point on the M4F and the M3) are
    // independent: the fixed-point ones (build, disassembly, QEMU and parse each) start in
    // their own threads while this one traces the f32 run, the longest (the counts come
    // from the execution log, so the host's load does not change them).
    let t1 = Instant::now();
    let (f32_run, t_qemu, fixed_runs) = std::thread::scope(|sc| {
        let handles: Vec<_> = FIXED_CORES
            .iter()
            .map(|fc| {
                let (qemu, tools) = (&qemu, &tools);
                sc.spawn(move || run_fixed(qemu, tools, fc))
            })
            .collect();
        let spec = RunSpec {
            profile_region,
            ..M4F_RUN
        };
        let f32_run = trace_regions(
            &qemu,
            &spec,
            &elf,
            &dis,
            &measured_graph,
            &markers,
            keep_trace.as_deref(),
        );
        let t_qemu = t1.elapsed();
        let fixed_runs: Vec<_> = handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err("a fixed-point run panicked".into()))
            })
            .collect();
        (f32_run, t_qemu, fixed_runs)
    });
    let t_fixed = t1.elapsed();
    let (stats, profile, summary) = f32_run?;

    // ---- results
    let base = stats.get("empty").cloned().unwrap_or_default();
    let (b_i, b_c) = (base.min_i, base.min_c);
    let mut regions = serde_json::Map::new();
    let mut rows = Vec::new();
    for name in REPORT_REGIONS {
        let s = stats.get(name).cloned().unwrap_or_default();
        if s.n == 0 {
            return Err(format!("region {name} was never measured"));
        }
        let (imin, imean, imax) = (
            s.min_i - b_i,
            s.sum_i as f64 / s.n as f64 - b_i as f64,
            s.max_i - b_i,
        );
        let (cmin, cmean, cmax) = (
            s.min_c - b_c,
            s.sum_c as f64 / s.n as f64 - b_c as f64,
            s.max_c - b_c,
        );
        let base_t = base.sum_t as f64 / base.n.max(1) as f64;
        let tmean = s.sum_t as f64 / s.n as f64 - base_t;
        let (down, up) = (
            s.sum_down as f64 / s.n as f64 - base.sum_down as f64 / base.n.max(1) as f64,
            s.sum_up as f64 / s.n as f64 - base.sum_up as f64 / base.n.max(1) as f64,
        );
        regions.insert(
            name.to_string(),
            serde_json::json!({
                "instructions": {"min": imin, "mean": round2(imean), "max": imax},
                "cycles_est": {"min": cmin, "mean": round2(cmean), "max": cmax},
                "cycles_table_only_mean": round2(tmean),
                "cycles_est_mean_range": [round2(cmean - down), round2(cmean + up)],
            }),
        );
        rows.push((name, s.n, imin, imean, imax, cmin, cmean, cmax));
    }
    let mean_c = |n: &str| {
        rows.iter()
            .find(|r| r.0 == n)
            .map(|r| r.6)
            .unwrap_or(f64::NAN)
    };
    let max_c = |n: &str| {
        rows.iter()
            .find(|r| r.0 == n)
            .map(|r| r.7 as f64)
            .unwrap_or(f64::NAN)
    };
    let ratio = mean_c("observer_full_order") / mean_c("observer_reduced");

    // ---- the fixed-point path on the Cortex-M4F and the Cortex-M3
    let results = bench_dir().join("results");
    std::fs::create_dir_all(&results).map_err(|e| e.to_string())?;
    let mut fixed_json = serde_json::Map::new();
    let mut fixed_rows: Vec<(&'static str, Vec<Row>, String)> = Vec::new();
    for (fc, run) in FIXED_CORES.iter().zip(fixed_runs) {
        let (frows, prof, fsummary) = run?;
        let mut m = serde_json::Map::new();
        for r in &frows {
            m.insert(r.name.clone(), region_json(r));
        }
        fixed_json.insert(
            fc.key.to_string(),
            serde_json::json!({
                "target": format!("{} (QEMU {} {}, cycles estimated from the {:?} timing table)", fc.target, qemu.version_string, fc.spec.machine, fc.spec.core),
                "regions": m,
            }),
        );
        let prof_path = results.join(format!("profile_fixed_{}_drive_step.txt", fc.key));
        std::fs::write(&prof_path, &prof).map_err(|e| e.to_string())?;
        fixed_rows.push((fc.key, frows, fsummary));
    }

    let json = serde_json::json!({
        "target": format!("{TARGET} (Cortex-M4F; instructions counted in QEMU {} netduinoplus2, cycles estimated from the Cortex-M4 TRM timings)", qemu.version_string),
        "regions": regions,
        "full_to_reduced_observer_ratio": round2(ratio),
        "fixed_point": fixed_json,
    });
    let out = results.join("cycles.json");
    std::fs::write(
        &out,
        serde_json::to_string_pretty(&json).map_err(|e| e.to_string())? + "\n",
    )
    .map_err(|e| format!("{}: {e}", out.display()))?;

    println!();
    println!(
        "{:<20} {:>5} {:>7} {:>9} {:>7} | {:>7} {:>9} {:>7} | {:>8}",
        "region", "n", "ins min", "ins mean", "ins max", "cyc min", "cyc mean", "cyc max", "us@170"
    );
    for r in &rows {
        println!(
            "{:<20} {:>5} {:>7} {:>9.1} {:>7} | {:>7} {:>9.1} {:>7} | {:>8.3}",
            r.0,
            r.1,
            r.2,
            r.3,
            r.4,
            r.5,
            r.6,
            r.7,
            r.6 / CLOCK_MHZ
        );
    }
    println!("(marker overhead subtracted: {b_i} instructions, {b_c} cycles)");
    if let Some(v) = regions.get("drive_step") {
        println!(
            "drive_step mean est. cycles from the timing table alone (no pipeline effects): {}; range left open by the model (branch refill 1-3, division overlap): {}",
            v["cycles_table_only_mean"], v["cycles_est_mean_range"]
        );
    }
    println!("full-order / reduced-order observer cost ratio (mean est. cycles): {ratio:.2}");
    let targets = [
        (
            "observer_reduced mean <= 60 est. cycles",
            mean_c("observer_reduced") <= 60.0,
        ),
        (
            "drive_step mean <= 750 est. cycles",
            mean_c("drive_step") <= 750.0,
        ),
        (
            "observer_reduced max <= 75 est. cycles",
            max_c("observer_reduced") <= 75.0,
        ),
        // the two-rate targets, on the ramp and at the steady loaded point
        (
            "two_rate_fast max <= 800 est. cycles",
            max_c("two_rate_fast") <= 800.0,
        ),
        (
            "two_rate_fast_loaded max <= 800 est. cycles",
            max_c("two_rate_fast_loaded") <= 800.0,
        ),
        (
            "two_rate_slow max <= 1500 est. cycles",
            max_c("two_rate_slow") <= 1500.0,
        ),
        (
            "two_rate_slow_loaded max <= 1500 est. cycles",
            max_c("two_rate_slow_loaded") <= 1500.0,
        ),
    ];
    for (t, ok) in targets {
        println!("target {t}: {}", if ok { "met" } else { "NOT met" });
    }
    println!("firmware: {summary}");

    for (key, frows, fsummary) in &fixed_rows {
        println!();
        println!(
            "fixed point (Q7.24) on {key}: {:<9} {:>5} {:>7} {:>9} {:>7} | {:>7} {:>9} {:>7}",
            "region", "n", "ins min", "ins mean", "ins max", "cyc min", "cyc mean", "cyc max"
        );
        for r in frows {
            println!(
                "{:<37} {:>5} {:>7} {:>9.1} {:>7} | {:>7} {:>9.1} {:>7}",
                r.name, r.n, r.imin, r.imean, r.imax, r.cmin, r.cmean, r.cmax
            );
        }
        println!("firmware: {fsummary}");
    }
    let fixed_mean_i = |key: &str, n: &str| {
        fixed_rows
            .iter()
            .find(|f| f.0 == key)
            .and_then(|f| f.1.iter().find(|r| r.name == n))
            .map(|r| r.imean)
            .unwrap_or(f64::NAN)
    };
    for (t, ok) in [
        (
            "fixed fast_step (the fast path between slow ticks) on m4f mean <= 1100 instructions",
            fixed_mean_i("m4f", "fast_step") <= 1100.0,
        ),
        (
            "fixed fast_step on m3 mean <= 1400 instructions",
            fixed_mean_i("m3", "fast_step") <= 1400.0,
        ),
        (
            "fixed observer_alone on m4f mean <= 100 instructions",
            fixed_mean_i("m4f", "observer_alone") <= 100.0,
        ),
    ] {
        println!("target {t}: {}", if ok { "met" } else { "NOT met" });
    }

    // ---- profile of the drive step
    let prof_path = results.join(format!("profile_{profile_region}.txt"));
    let prof_text = profile.render(
        &dis,
        rows.iter()
            .find(|r| r.0 == profile_region)
            .map(|r| r.1)
            .unwrap_or(1),
    );
    std::fs::write(&prof_path, &prof_text).map_err(|e| e.to_string())?;
    println!("{profile_region} profile: {}", prof_path.display());

    // ---- panic / f64 scan
    let mut ok = true;
    println!();
    println!(
        "static scan of bench_region_drive_step and its {} callees:",
        step_graph.functions.len() - 1
    );
    let findings = scan(&dis, &step_graph);
    for f in &findings.panics {
        println!("  PANIC PATH: {f}");
    }
    for f in &findings.f64 {
        println!("  F64 SOFT-FLOAT: {f}");
    }
    for f in &findings.other_calls {
        println!("  note: calls {f}");
    }
    for f in &findings.indirect {
        println!("  note: indirect branch in {f}");
    }
    if findings.panics.is_empty() && findings.f64.is_empty() {
        println!("  no panic and no f64 routine reachable from the drive step");
    } else if allow_panic_paths {
        println!("  (--allow-panic-paths: reported, not failing)");
    } else {
        ok = false;
    }
    let shadow_findings = scan(&dis, &measured_graph);
    if !shadow_findings.panics.is_empty() || !shadow_findings.f64.is_empty() {
        println!(
            "  (bench harness, all regions: panics {:?}, f64 {:?})",
            shadow_findings.panics, shadow_findings.f64
        );
    }
    if !measured_graph.indirect.is_empty() {
        println!("  warning: indirect calls in the measured code; -dfilter may hide callees");
    }
    if !summary.contains("mismatches=0")
        || summary.contains("drive_faulted=1")
        || summary.contains("two_rate_faulted=1")
    {
        println!("  PROBED STEP: the probed clone diverged from Drive::step or a drive faulted");
        ok = false;
    }

    // ---- budget
    let budget_path = bench_dir().join("budget.json");
    // every gated region: the f32 regions by name, the fixed-point ones as
    // `fixed_<core>.<region>`
    let mut gated: Vec<(String, u64)> = rows.iter().map(|r| (r.0.to_string(), r.4)).collect();
    for (key, frows, _) in &fixed_rows {
        gated.extend(
            frows
                .iter()
                .map(|r| (format!("fixed_{key}.{}", r.name), r.imax)),
        );
    }
    if update_budget {
        let mut b = serde_json::Map::new();
        for (name, max) in &gated {
            b.insert(name.clone(), serde_json::json!(max));
        }
        let doc = serde_json::json!({
            "comment": "max executed instructions per region (acim-bench, QEMU); --check fails above +5 %. Regenerate with: cargo run -p acim-bench --release -- --update-budget",
            "max_instructions": b,
        });
        std::fs::write(
            &budget_path,
            serde_json::to_string_pretty(&doc).unwrap() + "\n",
        )
        .map_err(|e| e.to_string())?;
        println!("budget written: {}", budget_path.display());
    }
    if check {
        let text = std::fs::read_to_string(&budget_path)
            .map_err(|e| format!("{}: {e}", budget_path.display()))?;
        let doc: serde_json::Value = serde_json::from_str(&text).map_err(|e| e.to_string())?;
        println!();
        println!(
            "budget check ({}, +{:.0} %):",
            budget_path.display(),
            BUDGET_TOLERANCE * 100.0
        );
        for (name, max) in &gated {
            match doc["max_instructions"][name.as_str()].as_u64() {
                Some(b) => {
                    let limit = b as f64 * (1.0 + BUDGET_TOLERANCE);
                    let pass = (*max as f64) <= limit;
                    println!(
                        "  {:<28} max {:>6} budget {:>6} {}",
                        name,
                        max,
                        b,
                        if pass { "ok" } else { "OVER BUDGET" }
                    );
                    ok &= pass;
                }
                None => {
                    println!("  {:<28} no budget entry", name);
                    ok = false;
                }
            }
        }
    }
    println!();
    println!(
        "time: build {:.1} s, QEMU run + parse {:.1} s (fixed point: {:.1} s); results: {}",
        t_build.as_secs_f64(),
        t_qemu.as_secs_f64(),
        t_fixed.as_secs_f64(),
        out.display()
    );
    Ok(ok)
}

/// The fixed-point path (`acim-bench-fixed`, the synthetic ideal current loop of
/// `src/bin/fixed_vs_f32.rs`) on one core: its regions, traced like the f32 bench.
struct FixedCore {
    /// Key of the results and budget entries (`fixed_<key>.<region>`).
    key: &'static str,
    target: &'static str,
    spec: RunSpec,
}

const FIXED_CORES: [FixedCore; 2] = [
    FixedCore {
        key: "m4f",
        target: "thumbv7em-none-eabihf",
        spec: RunSpec {
            machine: "netduinoplus2",
            cpu: "cortex-m4",
            core: Core::M4,
            summary_prefix: "ACIM-FIXED summary ",
            profile_region: "drive_step",
        },
    },
    FixedCore {
        key: "m3",
        target: "thumbv7m-none-eabi",
        spec: RunSpec {
            machine: "netduino2",
            cpu: "cortex-m3",
            core: Core::M3,
            summary_prefix: "ACIM-FIXED summary ",
            profile_region: "drive_step",
        },
    },
];

/// Marker regions of the fixed-point firmware (`bench_begin_fx_<region>`), `empty` first.
const FIXED_REGIONS: [&str; 12] = [
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

/// One measured region: name, samples, instructions min/mean/max, est. cycles min/mean/max
/// (marker overhead subtracted).
#[derive(Clone, Debug)]
struct Row {
    name: String,
    n: u64,
    imin: u64,
    imean: f64,
    imax: u64,
    cmin: u64,
    cmean: f64,
    cmax: u64,
    /// Mean estimate from the timing table alone (no pipeline effects).
    tmean: f64,
    /// Mean of the range the model leaves open ([`slack`]).
    range: (f64, f64),
}

fn rows_of(stats: &HashMap<&'static str, Stat>, names: &[&'static str]) -> Res<Vec<Row>> {
    let base = stats.get("empty").cloned().unwrap_or_default();
    let (b_i, b_c) = (base.min_i, base.min_c);
    names
        .iter()
        .filter(|n| **n != "empty")
        .map(|&name| {
            let s = stats.get(name).cloned().unwrap_or_default();
            if s.n == 0 {
                return Err(format!("region {name} was never measured"));
            }
            Ok(Row {
                name: name.to_string(),
                n: s.n,
                imin: s.min_i - b_i,
                imean: s.sum_i as f64 / s.n as f64 - b_i as f64,
                imax: s.max_i - b_i,
                cmin: s.min_c - b_c,
                cmean: s.sum_c as f64 / s.n as f64 - b_c as f64,
                cmax: s.max_c - b_c,
                tmean: s.sum_t as f64 / s.n as f64 - base.sum_t as f64 / base.n.max(1) as f64,
                range: {
                    let per = |v: u64, n: u64| v as f64 / n.max(1) as f64;
                    let c = per(s.sum_c, s.n) - b_c as f64;
                    (
                        c - (per(s.sum_down, s.n) - per(base.sum_down, base.n)),
                        c + (per(s.sum_up, s.n) - per(base.sum_up, base.n)),
                    )
                },
            })
        })
        .collect()
}

/// Builds, traces and weights the fixed-point firmware on `fc`'s core; the rows, the
/// drive-step profile (rendered) and the firmware summary.
fn run_fixed(qemu: &Qemu, tools: &Tools, fc: &FixedCore) -> Res<(Vec<Row>, String, String)> {
    let elf = build_bin(fc.target, "acim-bench-fixed")?;
    let dis = Disassembly::load(tools, &elf)?;
    let markers = dis.markers("fx_", &FIXED_REGIONS)?;
    // the measured work is out of line in fixed_step, fixed_step_probed, fixed_observer
    // (and the marker calibration): the trace filter covers them and their callees
    let mut roots: Vec<usize> = (0..dis.funcs.len())
        .filter(|&k| {
            let n = &dis.funcs[k].name;
            n.contains("::fw::fixed_step")
                || n.contains("::fw::fixed_observer")
                || n.contains("::fw::calibrate")
        })
        .collect();
    if roots.len() < 4 {
        return Err(format!(
            "{}: fixed_step, fixed_step_probed, fixed_observer, calibrate not all found",
            fc.key
        ));
    }
    roots.extend(markers.values().map(|m| m.func));
    let graph = dis.reachable(&roots);
    eprintln!("fixed point on {} ({}):", fc.key, fc.spec.machine);
    let (stats, profile, summary) =
        trace_regions(qemu, &fc.spec, &elf, &dis, &graph, &markers, None)?;
    if !summary.contains("measured=500") || !summary.contains("faults=0") {
        return Err(format!(
            "{}: the fixed-point run did not complete cleanly: {summary}",
            fc.key
        ));
    }
    let rows = rows_of(&stats, &FIXED_REGIONS)?;
    let steps = rows
        .iter()
        .find(|r| r.name == "drive_step")
        .map(|r| r.n)
        .unwrap_or(1);
    Ok((rows, profile.render(&dis, steps), summary))
}

fn region_json(r: &Row) -> serde_json::Value {
    serde_json::json!({
        "instructions": {"min": r.imin, "mean": round2(r.imean), "max": r.imax},
        "cycles_est": {"min": r.cmin, "mean": round2(r.cmean), "max": r.cmax},
        "cycles_table_only_mean": round2(r.tmean),
        "cycles_est_mean_range": [round2(r.range.0), round2(r.range.1)],
    })
}

/// The cycle target of the control interrupt, entry to return.
const ISR_CYCLE_TARGET: f64 = 1000.0;

/// Weighs the control interrupt's executed addresses recorded by the firmware-in-the-loop
/// suite (`firmware/fil`, one interrupt per line) with the Cortex-M4 model of [`timed`]:
/// instructions and estimated cycles per phase, held to `firmware/fil/isr-budget.json`.
fn weigh_isr_traces(elf: &Path, dir: &Path, check: bool, update: bool) -> Res<bool> {
    let tools = llvm_tools()?;
    let dis = Disassembly::load(&tools, elf)?;
    let budget_path = bench_dir().join("../firmware/fil/isr-budget.json");
    let mut doc: serde_json::Value = std::fs::read_to_string(&budget_path)
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_else(|| serde_json::json!({}));
    let mut ok = true;
    println!(
        "control interrupt ({}), Cortex-M4 model, zero wait states (CCM SRAM):",
        elf.display()
    );
    // the R-L load's phases (magnetizing, running) and the motor model's steady loaded
    // point, one rate, with a 1 ms slow task (the control interrupt alone) and with the
    // flux observer (`estimation.observer 1`)
    for phase in [
        "magnetizing",
        "running",
        "loaded",
        "loaded_two_rate",
        "loaded_flux",
    ] {
        let path = dir.join(format!("fil-isr-trace-{phase}.txt"));
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut st = Stat::default();
        let mut unknown = 0u64;
        let mut outside_ccm = BTreeSet::new();
        let mut by_func: BTreeMap<String, (u64, u64)> = BTreeMap::new();
        for line in text.lines().filter(|l| !l.trim().is_empty()) {
            let pcs: Vec<u32> = line
                .split_whitespace()
                .filter_map(|h| u32::from_str_radix(h, 16).ok())
                .collect();
            let (mut n, mut c, mut t) = (0u64, 0u64, 0u64);
            let (mut down, mut up) = (0u64, 0u64);
            let mut prev = Prev::default();
            let mut after_ls = false;
            for (k, &pc) in pcs.iter().enumerate() {
                if !(0x1000_0000..0x1000_8000).contains(&pc) {
                    outside_ccm.insert(dis.function_at(pc).map(|f| dis.funcs[f].name.clone()));
                }
                let Some(i) = dis.at(pc) else {
                    unknown += 1;
                    continue;
                };
                // the last one is the return (a write of the PC)
                let taken = pcs.get(k + 1).is_none_or(|&next| next != pc + i.size);
                let (ct, class) = cycles_on(Core::M4, i, taken, after_ls);
                after_ls = is_single_ls(class);
                let (cc, _, next) = timed(Core::M4, i, taken, &prev);
                prev = next;
                let (d, u) = slack(Core::M4, i, taken);
                (down, up) = (down + d as u64, up + u as u64);
                let f = by_func.entry(dis.funcs[i.func].name.clone()).or_default();
                f.0 += 1;
                f.1 += cc as u64;
                n += 1;
                c += cc as u64;
                t += ct as u64;
            }
            st.add(n, c, t);
            st.add_slack(down, up);
        }
        if st.n == 0 {
            return Err(format!("{}: no interrupt recorded", path.display()));
        }
        let mean_c = st.sum_c as f64 / st.n as f64;
        println!(
            "  {phase:<12} n {:>4}  instructions min {} mean {:.1} max {}  est. cycles min {} mean {:.1} max {} (table only: mean {:.1}) = {:.2} us at 170 MHz, {:.1} % of 200 us",
            st.n,
            st.min_i,
            st.sum_i as f64 / st.n as f64,
            st.max_i,
            st.min_c,
            mean_c,
            st.max_c,
            st.sum_t as f64 / st.n as f64,
            st.max_c as f64 / CLOCK_MHZ,
            st.max_c as f64 / CLOCK_MHZ / 2.0
        );
        let mut funcs: Vec<_> = by_func.into_iter().collect();
        funcs.sort_by_key(|f| std::cmp::Reverse(f.1 .1));
        for (name, (fi, fc)) in funcs {
            println!(
                "      {:>7.1} ins {:>7.1} cyc  {name}",
                fi as f64 / st.n as f64,
                fc as f64 / st.n as f64
            );
        }
        println!(
            "  {phase}: mean range left open by the model (branch refill 1-3, division overlap): {:.1} .. {:.1}",
            mean_c - st.sum_down as f64 / st.n as f64,
            mean_c + st.sum_up as f64 / st.n as f64
        );
        if unknown > 0 {
            println!("  {phase}: {unknown} executed addresses not in the disassembly");
            ok = false;
        }
        if !outside_ccm.is_empty() {
            println!("  {phase}: executed outside CCM SRAM: {outside_ccm:?}");
            ok = false;
        }
        println!(
            "  target: {phase} max <= {ISR_CYCLE_TARGET} est. cycles: {}",
            if st.max_c as f64 <= ISR_CYCLE_TARGET {
                "met"
            } else {
                "NOT met"
            }
        );
        let key = format!("{phase}_max_cycles_est");
        if update {
            doc[key.as_str()] = serde_json::json!(st.max_c);
        } else if check {
            match doc[key.as_str()].as_u64() {
                Some(b) => {
                    let pass = st.max_c as f64 <= b as f64 * (1.0 + BUDGET_TOLERANCE);
                    println!(
                        "  budget {key}: {} vs {b} {}",
                        st.max_c,
                        if pass { "ok" } else { "OVER BUDGET" }
                    );
                    ok &= pass;
                }
                None => {
                    println!("  no budget entry {key}");
                    ok = false;
                }
            }
        }
    }
    if update {
        std::fs::write(
            &budget_path,
            serde_json::to_string_pretty(&doc).map_err(|e| e.to_string())? + "\n",
        )
        .map_err(|e| format!("{}: {e}", budget_path.display()))?;
        println!("budget written: {}", budget_path.display());
    }
    Ok(ok)
}

fn round2(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}

// ------------------------------------------------------------------------------------
// building and tools
// ------------------------------------------------------------------------------------

fn cargo() -> String {
    std::env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

fn build_firmware() -> Res<PathBuf> {
    build_bin(TARGET, FW_BIN)
}

fn build_bin(target: &str, bin: &str) -> Res<PathBuf> {
    let mut cmd = Command::new(cargo());
    cmd.args([
        "build",
        "--profile",
        "firmware",
        "--target",
        target,
        "-p",
        "acim-bench",
        "--bin",
        bin,
        "--message-format=json-render-diagnostics",
    ])
    .current_dir(bench_dir())
    .stdout(Stdio::piped())
    .stderr(Stdio::inherit());
    eprintln!("building {bin} for {target} (profile firmware) ...");
    let out = cmd.output().map_err(|e| format!("cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "building the firmware failed (is the target installed? rustup target add {target})"
        ));
    }
    let mut exe = None;
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        if let Ok(v) = serde_json::from_str::<serde_json::Value>(line) {
            if v["reason"] == "compiler-artifact" && v["target"]["name"] == bin {
                if let Some(p) = v["executable"].as_str() {
                    exe = Some(PathBuf::from(p));
                }
            }
        }
    }
    exe.ok_or_else(|| "cargo did not report the firmware executable".into())
}

struct Tools {
    objdump: PathBuf,
}

fn llvm_tools() -> Res<Tools> {
    let rustc = std::env::var("RUSTC").unwrap_or_else(|_| "rustc".into());
    let sysroot = Command::new(&rustc)
        .args(["--print", "sysroot"])
        .output()
        .map_err(|e| format!("rustc: {e}"))?;
    let vv = Command::new(&rustc)
        .arg("-vV")
        .output()
        .map_err(|e| format!("rustc: {e}"))?;
    let host = String::from_utf8_lossy(&vv.stdout)
        .lines()
        .find_map(|l| l.strip_prefix("host: ").map(str::to_string))
        .ok_or("rustc -vV: no host line")?;
    let dir = PathBuf::from(String::from_utf8_lossy(&sysroot.stdout).trim())
        .join("lib/rustlib")
        .join(host)
        .join("bin");
    let objdump = dir.join("llvm-objdump");
    if !objdump.exists() {
        return Err(format!(
            "{} not found: rustup component add llvm-tools",
            objdump.display()
        ));
    }
    Ok(Tools { objdump })
}

// ------------------------------------------------------------------------------------
// disassembly
// ------------------------------------------------------------------------------------

#[derive(Clone, Debug)]
struct Insn {
    addr: u32,
    size: u32,
    mnemonic: String,
    operands: String,
    func: usize,
}

#[derive(Clone, Debug)]
struct Func {
    name: String,
    start: u32,
    end: u32,
}

struct Disassembly {
    funcs: Vec<Func>,
    /// Lowest instruction address (even).
    base: u32,
    /// Index into `insns` of the instruction at `base + 2 k` (Thumb instructions are
    /// halfword aligned), [`NO_INSN`] where none starts: a dense map from PC to
    /// instruction, looked up for every line of the execution log.
    table: Vec<u32>,
    insns: Vec<Insn>,
}

/// No instruction starts at this halfword (in [`Disassembly::table`]).
const NO_INSN: u32 = u32::MAX;

#[derive(Clone, Copy, Debug)]
struct Marker {
    region: &'static str,
    begin: bool,
    func: usize,
}

struct Graph {
    functions: BTreeSet<usize>,
    indirect: BTreeSet<usize>,
}

impl Disassembly {
    fn load(tools: &Tools, elf: &Path) -> Res<Self> {
        let out = Command::new(&tools.objdump)
            .args(["-d", "-C"])
            .arg(elf)
            .output()
            .map_err(|e| format!("llvm-objdump: {e}"))?;
        if !out.status.success() {
            return Err(format!("llvm-objdump failed on {}", elf.display()));
        }
        let text = String::from_utf8_lossy(&out.stdout);
        let mut funcs: Vec<Func> = Vec::new();
        let mut insns: Vec<Insn> = Vec::new();
        for line in text.lines() {
            // function label: "08000400 <Reset>:"
            if let Some(rest) = line.strip_suffix(">:") {
                if let Some((a, name)) = rest.split_once(" <") {
                    if let Ok(addr) = u32::from_str_radix(a.trim(), 16) {
                        if let Some(f) = funcs.last_mut() {
                            if f.end == 0 {
                                f.end = addr;
                            }
                        }
                        funcs.push(Func {
                            name: name.to_string(),
                            start: addr,
                            end: 0,
                        });
                    }
                }
                continue;
            }
            // instruction: " 8000400: b580         \tpush\t{r7, lr}"
            let Some((a, rest)) = line.split_once(':') else {
                continue;
            };
            let Ok(addr) = u32::from_str_radix(a.trim(), 16) else {
                continue;
            };
            if funcs.is_empty() {
                continue;
            }
            let mut parts = rest.split('\t');
            let raw = parts.next().unwrap_or("").trim();
            let size: u32 = raw.split_whitespace().map(|w| (w.len() / 2) as u32).sum();
            let mnemonic = parts.next().unwrap_or("").trim().to_string();
            let operands = parts.collect::<Vec<_>>().join("\t").trim().to_string();
            if size == 0 || mnemonic.is_empty() {
                continue;
            }
            insns.push(Insn {
                addr,
                size,
                mnemonic,
                operands,
                func: funcs.len() - 1,
            });
        }
        if let (Some(f), Some(i)) = (funcs.last_mut(), insns.last()) {
            if f.end == 0 {
                f.end = i.addr + i.size;
            }
        }
        if insns.is_empty() {
            return Err("empty disassembly".into());
        }
        let base = insns.iter().map(|i| i.addr).min().unwrap_or(0) & !1;
        let top = insns.iter().map(|i| i.addr + i.size).max().unwrap_or(0);
        let mut table = vec![NO_INSN; ((top - base) / 2 + 1) as usize];
        for (k, i) in insns.iter().enumerate() {
            table[((i.addr - base) / 2) as usize] = k as u32;
        }
        Ok(Self {
            funcs,
            base,
            table,
            insns,
        })
    }

    fn at(&self, pc: u32) -> Option<&Insn> {
        self.index(pc).map(|k| &self.insns[k])
    }

    /// Index into `insns` of the instruction at `pc`.
    fn index(&self, pc: u32) -> Option<usize> {
        let off = pc.checked_sub(self.base)? / 2;
        match self.table.get(off as usize) {
            Some(&k) if k != NO_INSN => Some(k as usize),
            _ => None,
        }
    }

    fn function_named(&self, pred: impl Fn(&str) -> bool) -> Option<usize> {
        self.funcs.iter().position(|f| pred(&f.name))
    }

    fn function_at(&self, addr: u32) -> Option<usize> {
        self.funcs
            .iter()
            .position(|f| f.start <= addr && addr < f.end.max(f.start + 1))
    }

    /// The marker functions `bench_begin_<prefix><region>` / `bench_end_<prefix><region>`.
    fn markers(&self, prefix: &str, regions: &[&'static str]) -> Res<HashMap<u32, Marker>> {
        let mut m = HashMap::new();
        for &r in regions {
            for begin in [true, false] {
                let name = format!("bench_{}_{prefix}{r}", if begin { "begin" } else { "end" });
                let func = self
                    .function_named(|n| n == name)
                    .ok_or_else(|| format!("marker {name} not found in the ELF"))?;
                let start = self.funcs[func].start;
                if m.insert(
                    start,
                    Marker {
                        region: r,
                        begin,
                        func,
                    },
                )
                .is_some()
                {
                    return Err(format!("marker {name} shares its address with another"));
                }
            }
        }
        Ok(m)
    }

    /// Functions reachable from `roots` through direct calls and branches to other
    /// functions (tail calls); indirect branches are recorded.
    fn reachable(&self, roots: &[usize]) -> Graph {
        let mut seen: BTreeSet<usize> = BTreeSet::new();
        let mut indirect = BTreeSet::new();
        let mut stack: Vec<usize> = roots.to_vec();
        let mut by_func: HashMap<usize, Vec<usize>> = HashMap::new();
        for (k, i) in self.insns.iter().enumerate() {
            by_func.entry(i.func).or_default().push(k);
        }
        while let Some(f) = stack.pop() {
            if !seen.insert(f) {
                continue;
            }
            for &k in by_func.get(&f).map(Vec::as_slice).unwrap_or(&[]) {
                let i = &self.insns[k];
                let base = base_mnemonic(&i.mnemonic);
                match base.as_str() {
                    "bl" | "b" | "blx" | "cbz" | "cbnz" => {
                        if let Some(t) = branch_target(&i.operands) {
                            if let Some(g) = self.function_at(t) {
                                if g != f {
                                    stack.push(g);
                                }
                            }
                        } else if base == "blx" || (base == "b" && !i.operands.is_empty()) {
                            indirect.insert(f);
                        }
                    }
                    "bx" if !i.operands.starts_with("lr") => {
                        indirect.insert(f);
                    }
                    _ => {}
                }
            }
        }
        Graph {
            functions: seen,
            indirect,
        }
    }

    /// `-dfilter` ranges covering the given functions (adjacent ones merged).
    fn dfilter(&self, funcs: &BTreeSet<usize>) -> String {
        let mut ranges: Vec<(u32, u32)> = funcs
            .iter()
            .map(|&f| (self.funcs[f].start, self.funcs[f].end))
            .collect();
        ranges.sort();
        let mut merged: Vec<(u32, u32)> = Vec::new();
        for (s, e) in ranges {
            match merged.last_mut() {
                Some(last) if s <= last.1 + 16 => last.1 = last.1.max(e),
                _ => merged.push((s, e)),
            }
        }
        merged
            .iter()
            .map(|(s, e)| format!("0x{s:x}..0x{:x}", e.saturating_sub(1).max(*s)))
            .collect::<Vec<_>>()
            .join(",")
    }
}

fn branch_target(ops: &str) -> Option<u32> {
    // "0x8007a0c <bench_begin_drive_step> @ imm = ..." or "r0, 0x80077e6 <...>"
    ops.split([' ', ',', '\t'])
        .find_map(|w| w.strip_prefix("0x"))
        .and_then(|h| u32::from_str_radix(h, 16).ok())
}

const CONDS: [&str; 16] = [
    "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le",
];

const KNOWN: &[&str] = &[
    "adc", "add", "addw", "adr", "and", "asr", "b", "bfc", "bfi", "bic", "bkpt", "bl", "blx", "bx",
    "cbnz", "cbz", "clz", "cmn", "cmp", "cpsid", "cpsie", "dmb", "dsb", "eor", "isb", "it", "ite",
    "itt", "itee", "itet", "itte", "ittt", "iteee", "iteet", "itete", "itett", "ittee", "ittet",
    "ittte", "itttt", "ldm", "ldmdb", "ldmia", "ldr", "ldrb", "ldrd", "ldrex", "ldrh", "ldrsb",
    "ldrsh", "lsl", "lsr", "mla", "mls", "mov", "movt", "movw", "mrs", "msr", "mul", "mvn", "nop",
    "orn", "orr", "pop", "push", "rbit", "rev", "rev16", "revsh", "ror", "rrx", "rsb", "sbc",
    "sbfx", "sdiv", "smlal", "smull", "ssat", "stm", "stmdb", "stmia", "str", "strb", "strd",
    "strex", "strh", "sub", "subw", "svc", "sxtb", "sxth", "tbb", "tbh", "teq", "tst", "ubfx",
    "udf", "udiv", "umlal", "umull", "usat", "uxtb", "uxth", "vabs", "vadd", "vcmp", "vcmpe",
    "vcvt", "vcvtr", "vdiv", "vfma", "vfms", "vfnma", "vfnms", "vldm", "vldmia", "vldmdb", "vldr",
    "vmla", "vmls", "vmov", "vmrs", "vmsr", "vmul", "vneg", "vnmla", "vnmls", "vnmul", "vpop",
    "vpush", "vsqrt", "vstm", "vstmia", "vstmdb", "vstr", "vsub", "wfi", "yield", "smmul", "smmla",
    "umaal", "pld",
];

/// Mnemonic without the width qualifier, data type, condition code and S suffix.
fn base_mnemonic(m: &str) -> String {
    let head = m.split('.').next().unwrap_or(m).to_ascii_lowercase();
    if KNOWN.contains(&head.as_str()) {
        return head;
    }
    for c in CONDS {
        if let Some(h) = head.strip_suffix(c) {
            if KNOWN.contains(&h) {
                return h.to_string();
            }
            if let Some(h2) = h.strip_suffix('s') {
                if KNOWN.contains(&h2) {
                    return h2.to_string();
                }
            }
        }
    }
    if let Some(h) = head.strip_suffix('s') {
        if KNOWN.contains(&h) {
            return h.to_string();
        }
    }
    head
}

fn reg_count(ops: &str) -> u32 {
    // "{r4, r5, r6, r7, lr}" or "{d8, d9}" or "r3, {r0, r1, r2, r3}" or "{s16-s19}"
    let Some(start) = ops.find('{') else { return 1 };
    let end = ops[start..]
        .find('}')
        .map(|e| start + e)
        .unwrap_or(ops.len());
    let mut n = 0;
    for r in ops[start + 1..end].split(',') {
        let r = r.trim();
        let w = if r.starts_with('d') { 2 } else { 1 };
        if let Some((a, b)) = r.split_once('-') {
            let num = |x: &str| {
                x.trim()
                    .trim_start_matches(|c: char| c.is_alphabetic())
                    .parse::<u32>()
                    .ok()
            };
            if let (Some(a), Some(b)) = (num(a), num(b)) {
                n += (b.saturating_sub(a) + 1) * w;
                continue;
            }
        }
        n += w;
    }
    n.max(1)
}

/// Instruction class for the profile and the pipelining rule.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
enum Class {
    Alu,
    Mul,
    Div,
    LoadStore,
    LoadStoreDouble,
    LoadStoreMultiple,
    Branch,
    Call,
    It,
    FpAluMov,
    FpLoadStore,
    FpMultiple,
    FpMac,
    FpDivSqrt,
    Other,
}

/// Estimated Cortex-M4 cycles of one executed instruction (see the table in the crate
/// docs). `taken`: the next executed PC is not the next instruction; `after_ls`: the
/// previous executed instruction was a single load/store.
fn cycles(i: &Insn, taken: bool, after_ls: bool) -> (u32, Class) {
    let b = base_mnemonic(&i.mnemonic);
    let ops = i.operands.as_str();
    let writes_pc =
        ops.starts_with("pc") || (ops.contains("pc}") && (b == "pop" || b.starts_with("ldm")));
    let refill = 2;
    match b.as_str() {
        "ldr" | "ldrb" | "ldrh" | "ldrsb" | "ldrsh" | "ldrex" | "str" | "strb" | "strh"
        | "strex" => {
            let c = if after_ls { 1 } else { 2 };
            (c + if writes_pc { refill } else { 0 }, Class::LoadStore)
        }
        "ldrd" | "strd" => (3, Class::LoadStoreDouble),
        "ldm" | "ldmia" | "ldmdb" | "stm" | "stmia" | "stmdb" | "push" | "pop" => {
            let n = reg_count(ops);
            (
                1 + n + if writes_pc { refill } else { 0 },
                Class::LoadStoreMultiple,
            )
        }
        "b" | "cbz" | "cbnz" => (if taken { 1 + refill } else { 1 }, Class::Branch),
        "bl" | "blx" => (1 + refill, Class::Call),
        "bx" => (1 + refill, Class::Branch),
        "tbb" | "tbh" => (2 + refill, Class::Branch),
        "mla" | "mls" => (2, Class::Mul),
        "mul" | "smull" | "umull" | "smlal" | "umlal" | "smmul" | "smmla" | "umaal" => {
            (1, Class::Mul)
        }
        "sdiv" | "udiv" => (12, Class::Div),
        "vldr" | "vstr" => (2, Class::FpLoadStore),
        "vldm" | "vldmia" | "vldmdb" | "vstm" | "vstmia" | "vstmdb" | "vpush" | "vpop" => {
            (1 + reg_count(ops), Class::FpMultiple)
        }
        "vmla" | "vmls" | "vnmla" | "vnmls" | "vfma" | "vfms" | "vfnma" | "vfnms" => {
            (3, Class::FpMac)
        }
        "vdiv" | "vsqrt" => (14, Class::FpDivSqrt),
        "vmov" => {
            // two core registers <-> two singles or a double: 2
            let n_ops = ops.split(',').count();
            (
                if n_ops >= 3 || ops.contains(" d") || ops.starts_with('d') {
                    2
                } else {
                    1
                },
                Class::FpAluMov,
            )
        }
        "vadd" | "vsub" | "vmul" | "vnmul" | "vabs" | "vneg" | "vcmp" | "vcmpe" | "vcvt"
        | "vcvtr" | "vmrs" | "vmsr" => (1, Class::FpAluMov),
        b if b.starts_with("it") => (1, Class::It),
        _ if KNOWN.contains(&b.as_str()) => (1 + if writes_pc { refill } else { 0 }, Class::Alu),
        _ => (1, Class::Other),
    }
}

/// The core whose timing table weights the executed instructions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Core {
    /// Cortex-M4F (Arm Cortex-M4 TRM r0p1, tables 3-1 and 7-1).
    M4,
    /// Cortex-M3 (Arm Cortex-M3 TRM r2p1, table 3-1): as the M4 except the long
    /// multiplies, which terminate early by operand size: UMULL 3-4, SMULL 4-5, UMLAL
    /// 4-6, SMLAL 5-7 (the signed forms one cycle longer); the worst case is taken.
    M3,
}

/// What an instruction's timing depends on from the instruction executed before it
/// (the pipeline model of [`timed`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Prev {
    /// The previous instruction was a single load (LDR/LDRB/LDRH/LDRSB/LDRSH, not a
    /// store, LDRD or LDM) into this core register (`u8::MAX`: the register is unknown).
    ldr_dest: Option<u8>,
    /// Single-precision registers (bit n = register `sn`) written by the previous instruction
    /// whose result arrives one cycle after it issues (VADD/VSUB/VMUL/VNMUL/VCVT: result
    /// latency 2; VMLA/VMLS/VNMLA/VNMLS and the fused forms: 4 after 3 issue cycles;
    /// VDIV/VSQRT: 15 after 14).
    fp_late: u32,
    /// The late result comes from VADD/VSUB/VMUL/VNMUL/VCVT, which forward to the addend
    /// of a following multiply-accumulate without a stall.
    fp_bypass: bool,
}

/// Single-precision register mask of one operand token (`s5`, `d3` = s6+s7).
fn fp_reg_mask(tok: &str) -> u32 {
    let t = tok
        .trim()
        .trim_matches(|c| c == '{' || c == '}' || c == '[' || c == ']');
    let num = |x: &str| x.parse::<u32>().ok();
    if let Some(n) = t.strip_prefix('s').and_then(num) {
        if n < 32 {
            return 1 << n;
        }
    }
    if let Some(n) = t.strip_prefix('d').and_then(num) {
        if n < 16 {
            return 3 << (2 * n);
        }
    }
    0
}

/// Mask of every single-precision register named in `ops` (ranges `s16-s19` included).
fn fp_mask_all(ops: &str) -> u32 {
    let mut m = 0;
    for tok in ops.split([',', ' ', '{', '}']) {
        if let Some((a, b)) = tok.split_once('-') {
            let (ma, mb) = (fp_reg_mask(a), fp_reg_mask(b));
            if ma != 0 && mb != 0 {
                let (lo, hi) = (ma.trailing_zeros(), 31 - mb.leading_zeros());
                for k in lo..=hi {
                    m |= 1 << k;
                }
                continue;
            }
        }
        m |= fp_reg_mask(tok);
    }
    m
}

/// Core register number of a token (`r0`-`r12`, `sp`, `lr`, `pc`).
fn core_reg(tok: &str) -> Option<u8> {
    let t = tok
        .trim()
        .trim_matches(|c| c == '{' || c == '}' || c == '[' || c == ']' || c == '!');
    match t {
        "sp" => Some(13),
        "lr" => Some(14),
        "pc" => Some(15),
        _ => t.strip_prefix('r')?.parse::<u8>().ok().filter(|&n| n < 16),
    }
}

/// Core registers inside the address brackets of a load/store (`[r1, r2, lsl #2]`).
fn address_regs(ops: &str) -> Vec<u8> {
    let Some(a) = ops.find('[') else {
        return vec![];
    };
    let b = ops[a..].find(']').map(|e| a + e).unwrap_or(ops.len());
    ops[a + 1..b].split(',').filter_map(core_reg).collect()
}

/// Estimated cycles on `core` of one executed instruction with its predecessor's state
/// `prev`; the class and the state for the next instruction.
///
/// The pipeline model on top of the table of [`cycles`] (Arm Cortex-M4 TRM r0p1 section
/// 3.3.2 and table 7-1; GCC's Cortex-M4 FPU pipeline description for the FP result
/// latencies, which the TRM does not tabulate):
/// - a single LDR directly after another single LDR costs 1 (address and data phases
///   pipelined) unless the first one's destination forms the second one's address; a
///   store is never followed by a pipelined access; a store with an immediate offset
///   costs 1 (its data phase overlaps the next instruction), with a register offset 2, or
///   1 directly after an LDR;
/// - an FP result used by the next instruction stalls it one cycle (VADD, VSUB, VMUL,
///   VNMUL, VCVT: result latency 2; multiply-accumulates 4 after 3 issue cycles; VDIV and
///   VSQRT 15 after 14), except a VADD/VSUB/VMUL/VNMUL/VCVT result forwarded to the
///   addend of a following multiply-accumulate; VABS/VNEG/VMOV between S registers,
///   VLDR and VMOV from a core register have no extra latency;
/// - VMOV of one float to or from a core register costs 2 (TRM table 7-1, "two
///   floats/one double to/from two core registers or one float to/from one core
///   register"), between S registers or an immediate 1.
fn timed(core: Core, i: &Insn, taken: bool, prev: &Prev) -> (u32, Class, Prev) {
    let t = Timing::of(core, i);
    let (c, next) = t.step(taken, prev);
    (c, t.class, next)
}

/// [`timed`] split into what depends on the instruction alone, decoded once from its
/// mnemonic and operands ([`Timing::of`]), and the little that depends on the executed
/// predecessor ([`Timing::step`]): the trace parse runs the step for every executed
/// instruction and the string analysis once per static instruction.
#[derive(Clone, Copy, Debug)]
struct Timing {
    /// Timing-table cycles ([`cycles_on`], not after a load/store), not taken / taken.
    table: [u32; 2],
    class: Class,
    access: Access,
    /// An FP instruction (`v...`): it may wait for the previous one's late result.
    fp: bool,
    /// Single-precision registers it reads (bit n = `sn`, see [`fp_sources`]).
    fp_reads: u32,
    /// A multiply-accumulate's addend (its destination): a VADD/VSUB/VMUL/VNMUL/VCVT
    /// result is forwarded to it without a stall; 0 for other instructions.
    fp_forwarded: u32,
    /// The state it leaves for the next instruction (depends on this one alone).
    next: Prev,
}

/// The load/store pipelining cases of [`timed`].
#[derive(Clone, Copy, Debug)]
enum Access {
    /// LDR/LDRB/LDRH/LDRSB/LDRSH; bit n: core register `rn` forms the address.
    Load {
        address_regs: u16,
    },
    /// STR/STRB/STRH with a register offset (else an immediate one).
    Store {
        reg_offset: bool,
    },
    /// VMOV of one float to or from a core register.
    CoreVmov,
    Other,
}

impl Timing {
    fn of(core: Core, i: &Insn) -> Self {
        let b = base_mnemonic(&i.mnemonic);
        let ops = i.operands.as_str();
        let toks: Vec<&str> = ops.split(',').map(str::trim).collect();
        let dest_mask = toks.first().map(|t| fp_reg_mask(t)).unwrap_or(0);
        let mut next = Prev::default();
        let access = match b.as_str() {
            "ldr" | "ldrb" | "ldrh" | "ldrsb" | "ldrsh" => {
                if !ops.starts_with("pc") {
                    next.ldr_dest = Some(toks.first().and_then(|t| core_reg(t)).unwrap_or(u8::MAX));
                }
                // core_reg() numbers are below 16
                let address_regs = address_regs(ops).iter().fold(0u16, |m, &r| m | 1 << r);
                Access::Load { address_regs }
            }
            "str" | "strb" | "strh" => Access::Store {
                reg_offset: address_regs(ops).len() > 1,
            },
            // one float to/from one core register: 2 (two core registers: 2 already)
            "vmov" if toks.iter().any(|t| core_reg(t).is_some()) => Access::CoreVmov,
            _ => Access::Other,
        };
        let late = matches!(
            b.as_str(),
            "vadd" | "vsub" | "vmul" | "vnmul" | "vcvt" | "vcvtr" | "vdiv" | "vsqrt"
        ) || is_fp_mac(&b);
        if late {
            next.fp_late = dest_mask;
            next.fp_bypass = matches!(
                b.as_str(),
                "vadd" | "vsub" | "vmul" | "vnmul" | "vcvt" | "vcvtr"
            );
        }
        let (not_taken, class) = cycles_on(core, i, false, false);
        Self {
            table: [not_taken, cycles_on(core, i, true, false).0],
            class,
            access,
            fp: b.starts_with('v'),
            fp_reads: fp_sources(&b, &toks),
            fp_forwarded: if is_fp_mac(&b) { dest_mask } else { 0 },
            next,
        }
    }

    /// Cycles when executed after an instruction that left `prev`; the state for the
    /// next one.
    fn step(&self, taken: bool, prev: &Prev) -> (u32, Prev) {
        let mut c = self.table[taken as usize];
        match self.access {
            Access::Load { address_regs } => {
                // pipelined behind a single load unless that load's destination forms
                // this one's address (u8::MAX: the destination is unknown)
                if let Some(d) = prev.ldr_dest {
                    if d != u8::MAX && address_regs & (1 << d) == 0 {
                        c -= 1;
                    }
                }
            }
            Access::Store { reg_offset } => {
                c = if !reg_offset || prev.ldr_dest.is_some() {
                    1
                } else {
                    2
                };
            }
            Access::CoreVmov => c = 2,
            Access::Other => {}
        }
        // FP result-use stall
        if prev.fp_late != 0 && self.fp {
            let mut hit = prev.fp_late & self.fp_reads;
            if prev.fp_bypass {
                // the addend of a multiply-accumulate is forwarded
                hit &= !self.fp_forwarded;
            }
            if hit != 0 {
                c += 1;
            }
        }
        (c, self.next)
    }
}

fn is_fp_mac(b: &str) -> bool {
    matches!(
        b,
        "vmla" | "vmls" | "vnmla" | "vnmls" | "vfma" | "vfms" | "vfnma" | "vfnms"
    )
}

/// Single-precision registers an FP instruction reads.
fn fp_sources(b: &str, toks: &[&str]) -> u32 {
    let all = |ts: &[&str]| ts.iter().fold(0, |m, t| m | fp_mask_all(t));
    match b {
        // destination first, then sources
        "vadd" | "vsub" | "vmul" | "vnmul" | "vdiv" | "vsqrt" | "vabs" | "vneg" | "vcvt"
        | "vcvtr" => all(toks.get(1..).unwrap_or(&[])),
        // the destination is the addend
        _ if is_fp_mac(b) => all(toks),
        // stores, compares, pushes: every named register is read
        "vstr" | "vstm" | "vstmia" | "vstmdb" | "vpush" | "vcmp" | "vcmpe" => all(toks),
        // vmov: the source is the last operand(s) after the destination
        "vmov" => all(toks.get(1..).unwrap_or(&[])),
        _ => 0,
    }
}

/// Estimated cycles of one executed instruction on `core` from the timing table alone
/// (see [`cycles`]; the pipeline effects are in [`timed`]).
fn cycles_on(core: Core, i: &Insn, taken: bool, after_ls: bool) -> (u32, Class) {
    let (c, class) = cycles(i, taken, after_ls);
    if core == Core::M3 {
        let extra = match base_mnemonic(&i.mnemonic).as_str() {
            "umull" => 3,
            "smull" => 4,
            "umlal" => 5,
            "smlal" => 6,
            _ => 0,
        };
        return (c + extra, class);
    }
    (c, class)
}

/// What the estimate of one executed instruction leaves open (cycles it may be too high,
/// too low): a pipeline refill is 1 to 3 cycles (TRM: "P ranges from 1 to 3 depending on
/// the alignment and width of the target instruction, and whether the processor manages to
/// speculate the address early"; 2 is taken); VDIV/VSQRT let the integer instructions
/// behind them complete (up to 13 of their 14 cycles overlapped); the M3's long multiplies
/// terminate early on small operands (the worst case is taken).
fn slack(core: Core, i: &Insn, taken: bool) -> (u32, u32) {
    let b = base_mnemonic(&i.mnemonic);
    let ops = i.operands.as_str();
    let writes_pc =
        ops.starts_with("pc") || (ops.contains("pc}") && (b == "pop" || b.starts_with("ldm")));
    let refill = match b.as_str() {
        "b" | "cbz" | "cbnz" => taken,
        "bl" | "blx" | "bx" | "tbb" | "tbh" => true,
        _ => writes_pc,
    };
    let mut s = if refill { (1, 1) } else { (0, 0) };
    match b.as_str() {
        "vdiv" | "vsqrt" => s.0 += 13,
        "umull" | "smull" if core == Core::M3 => s.0 += 1,
        "umlal" | "smlal" if core == Core::M3 => s.0 += 2,
        _ => {}
    }
    s
}

fn is_single_ls(class: Class) -> bool {
    class == Class::LoadStore
}

// ------------------------------------------------------------------------------------
// trace filter
// ------------------------------------------------------------------------------------

/// The compiler's soft-float runtime routines (single and double precision): the
/// `__aeabi_f*` / `__aeabi_d*` entry points, the integer-to-float conversions and
/// compiler_builtins' `float` module.
fn is_soft_float(name: &str) -> bool {
    is_f64(name)
        || name.starts_with("__aeabi_f")
        || (name.starts_with("__aeabi_") && name.ends_with("2f"))
        || name.contains("compiler_builtins::float::")
        || (name.starts_with("__")
            && (name.ends_with("sf3")
                || name.ends_with("sf2")
                || name.contains("sfsi")
                || name.contains("sisf")
                || name.contains("sfdi")
                || name.contains("disf")))
}

/// The `-dfilter` of one traced run, and the branches that leave it.
///
/// QEMU logs every executed instruction inside the ranges, in a measured region or not,
/// and a logged instruction costs QEMU about 20 times an unlogged one (formatting, one
/// write and flush per line). The static call graph of the measured code reaches the
/// soft-float routines through paths the measured regions do not take, while the
/// firmware's unmeasured code calls them all the time: on the Cortex-M3 the f32 drive
/// beside the fixed-point one runs about 17000 of their instructions per step: 152
/// million log lines per run, 2.6 million without them. [`TraceFilter::narrowed`]
/// leaves them out of the ranges. The counts stay exact as long as no measured region
/// enters them, and the trace shows whether one does: without indirect branches in the
/// graph (a condition of the narrowing) and without interrupts (assumed throughout), the
/// logged code enters them only by a direct branch or call, so every instruction with
/// such a target is flagged, and a region that executes one (taken or not) has the run
/// repeated with the whole graph ([`trace_regions`]). Outside the regions a left-out
/// line changes nothing: an instruction's timing depends only on the instruction
/// executed just before it, and a region's first one follows its begin marker's return.
struct TraceFilter {
    /// The `-dfilter` argument.
    ranges: String,
    /// Per instruction of the disassembly: a direct branch or call into code the ranges
    /// leave out (empty: nothing is left out).
    leaves: Vec<bool>,
}

impl TraceFilter {
    /// Every function of `graph`.
    fn full(dis: &Disassembly, graph: &Graph) -> Self {
        Self {
            ranges: dis.dfilter(&graph.functions),
            leaves: Vec::new(),
        }
    }

    /// `graph` without its soft-float routines; `None` when it has none or has indirect
    /// branches.
    fn narrowed(dis: &Disassembly, graph: &Graph) -> Option<Self> {
        let left_out: BTreeSet<usize> = graph
            .functions
            .iter()
            .copied()
            .filter(|&f| is_soft_float(&dis.funcs[f].name))
            .collect();
        if left_out.is_empty() || !graph.indirect.is_empty() {
            return None;
        }
        let kept: BTreeSet<usize> = graph.functions.difference(&left_out).copied().collect();
        // the branches of `Disassembly::reachable`, to a left-out function
        let leaves = dis
            .insns
            .iter()
            .map(|i| {
                branch_target(&i.operands)
                    .and_then(|t| dis.function_at(t))
                    .is_some_and(|g| left_out.contains(&g))
                    && matches!(
                        base_mnemonic(&i.mnemonic).as_str(),
                        "bl" | "b" | "blx" | "cbz" | "cbnz"
                    )
            })
            .collect();
        Some(Self {
            ranges: dis.dfilter(&kept),
            leaves,
        })
    }
}

// ------------------------------------------------------------------------------------
// QEMU
// ------------------------------------------------------------------------------------

/// What the trace parse needs of one static instruction on one core, decoded once (on
/// its first execution) by the functions that define the model.
#[derive(Clone, Copy, Debug)]
struct Weights {
    /// [`cycles_on`], the timing table alone: `[taken][after a single load/store]`.
    table: [[u32; 2]; 2],
    /// A single load/store ([`is_single_ls`]; the class depends on the mnemonic alone).
    single_ls: bool,
    /// The pipeline model ([`timed`]).
    timing: Timing,
    /// [`slack`]: `[taken]`.
    slack: [(u32, u32); 2],
}

impl Weights {
    fn of(core: Core, i: &Insn) -> Self {
        let table = |taken| {
            [
                cycles_on(core, i, taken, false).0,
                cycles_on(core, i, taken, true).0,
            ]
        };
        let timing = Timing::of(core, i);
        Self {
            table: [table(false), table(true)],
            single_ls: is_single_ls(timing.class),
            timing,
            slack: [slack(core, i, false), slack(core, i, true)],
        }
    }
}

/// After a read shorter than this (bytes), [`BatchedPipe`] waits before the next one.
const LOG_SHORT_READ: usize = 16 << 10;
/// How long [`BatchedPipe`] lets the log accumulate after a short read.
const LOG_BATCH_WAIT: Duration = Duration::from_micros(500);

/// QEMU's execution log read from its pipe in batches. QEMU writes and flushes one line
/// per executed instruction (about 50 kB per ms); a reader that keeps up is woken for
/// every line, and those wake-ups cost more system time in both processes than the
/// parse. After a short read this one waits [`LOG_BATCH_WAIT`], so the next read
/// returns tens of kilobytes (the pipe holds 64 kB; measured on the f32 run: QEMU 27 s
/// instead of 60 s, against 19 s logging to /dev/null).
struct BatchedPipe<R> {
    inner: R,
    wait: bool,
}

impl<R: Read> Read for BatchedPipe<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        if self.wait {
            std::thread::sleep(LOG_BATCH_WAIT);
        }
        let n = self.inner.read(buf)?;
        self.wait = n < LOG_SHORT_READ;
        Ok(n)
    }
}

/// The guest PC of one `-d exec` line, "Trace 0: 0x7f.. [00800408/08000400/00000110/ff000201]
/// Reset": the second field in the brackets (the first is the block's cs_base), hex.
fn trace_pc(line: &[u8]) -> Option<u32> {
    let open = line.iter().position(|&c| c == b'[')?;
    let rest = &line[open + 1..];
    let s1 = rest.iter().position(|&c| c == b'/')?;
    let rest = &rest[s1 + 1..];
    let s2 = rest.iter().position(|&c| c == b'/')?;
    parse_hex_u32(&rest[..s2])
}

/// Hex digits (either case) as a `u32`; `None` when empty, not hex, or over 32 bits.
fn parse_hex_u32(digits: &[u8]) -> Option<u32> {
    if digits.is_empty() {
        return None;
    }
    digits.iter().try_fold(0u32, |v, &c| {
        let d = (c as char).to_digit(16)?;
        v.checked_mul(16)?.checked_add(d)
    })
}

struct Qemu {
    one_insn_args: Vec<String>,
    version_string: String,
}

impl Qemu {
    fn detect() -> Res<Self> {
        let out = Command::new("qemu-system-arm")
            .arg("--version")
            .output()
            .map_err(|e| {
                format!("qemu-system-arm not found ({e}): apt-get install qemu-system-arm")
            })?;
        let text = String::from_utf8_lossy(&out.stdout).to_string();
        // "QEMU emulator version 7.2.x (Debian ...)"
        let ver = text
            .split_whitespace()
            .skip_while(|w| *w != "version")
            .nth(1)
            .unwrap_or("0.0")
            .to_string();
        let mut it = ver.split('.').map(|x| x.parse::<u32>().unwrap_or(0));
        let (major, minor) = (it.next().unwrap_or(0), it.next().unwrap_or(0));
        // QEMU 8.1 deprecated -singlestep for -accel tcg,one-insn-per-tb=on (removed in 9.0)
        let one_insn_args = if (major, minor) >= (8, 1) {
            vec!["-accel".into(), "tcg,one-insn-per-tb=on".into()]
        } else {
            vec!["-singlestep".into()]
        };
        Ok(Self {
            one_insn_args,
            version_string: ver,
        })
    }
}

#[derive(Clone, Debug, Default)]
struct Stat {
    n: u64,
    min_i: u64,
    max_i: u64,
    sum_i: u64,
    min_c: u64,
    max_c: u64,
    sum_c: u64,
    /// Sum of the estimate from the timing table alone (the model before the pipeline
    /// effects of [`timed`]), for comparison.
    sum_t: u64,
    /// Sums of the model's unmodelled slack (cycles the estimate may be too high, too
    /// low): see [`slack`].
    sum_down: u64,
    sum_up: u64,
}

impl Stat {
    fn add_slack(&mut self, down: u64, up: u64) {
        self.sum_down += down;
        self.sum_up += up;
    }

    fn add(&mut self, i: u64, c: u64, t: u64) {
        self.sum_t += t;
        if self.n == 0 {
            self.min_i = i;
            self.max_i = i;
            self.min_c = c;
            self.max_c = c;
        } else {
            self.min_i = self.min_i.min(i);
            self.max_i = self.max_i.max(i);
            self.min_c = self.min_c.min(c);
            self.max_c = self.max_c.max(c);
        }
        self.n += 1;
        self.sum_i += i;
        self.sum_c += c;
    }
}

/// Per-instruction execution counts and cycles inside the drive-step region.
#[derive(Default)]
struct Profile {
    by_pc: HashMap<u32, (u64, u64)>,
}

impl Profile {
    fn render(&self, dis: &Disassembly, steps: u64) -> String {
        let steps = steps.max(1) as f64;
        let mut by_func: BTreeMap<String, (u64, u64)> = BTreeMap::new();
        let mut by_class: BTreeMap<String, (u64, u64)> = BTreeMap::new();
        let mut by_mnem: BTreeMap<String, (u64, u64)> = BTreeMap::new();
        let (mut ti, mut tc) = (0u64, 0u64);
        for (&pc, &(n, c)) in &self.by_pc {
            let Some(i) = dis.at(pc) else { continue };
            let f = by_func.entry(dis.funcs[i.func].name.clone()).or_default();
            f.0 += n;
            f.1 += c;
            let (_, class) = cycles(i, false, false);
            let k = by_class.entry(format!("{class:?}")).or_default();
            k.0 += n;
            k.1 += c;
            let m = by_mnem.entry(i.mnemonic.clone()).or_default();
            m.0 += n;
            m.1 += c;
            ti += n;
            tc += c;
        }
        let mut s = String::new();
        s.push_str(&format!(
            "Region profile (acim-bench): per call, averaged over {steps} calls; total {:.1} instructions, {:.1} est. cycles (marker overhead not subtracted)\n\n",
            ti as f64 / steps,
            tc as f64 / steps
        ));
        let table = |s: &mut String, title: &str, m: &BTreeMap<String, (u64, u64)>| {
            s.push_str(&format!(
                "## {title}\n{:>10} {:>10}  name\n",
                "ins/step", "cyc/step"
            ));
            let mut v: Vec<_> = m.iter().collect();
            v.sort_by_key(|e| std::cmp::Reverse(e.1 .1));
            for (k, (n, c)) in v {
                s.push_str(&format!(
                    "{:>10.1} {:>10.1}  {}\n",
                    *n as f64 / steps,
                    *c as f64 / steps,
                    k
                ));
            }
            s.push('\n');
        };
        table(&mut s, "by function", &by_func);
        table(&mut s, "by instruction class", &by_class);
        table(&mut s, "by mnemonic", &by_mnem);
        // hottest instructions in address order
        s.push_str("## instructions executed in the step (address order)\n");
        s.push_str(&format!(
            "{:>9} {:>8}  address   instruction\n",
            "ins/step", "cyc/step"
        ));
        let mut pcs: Vec<_> = self.by_pc.keys().copied().collect();
        pcs.sort();
        let mut last_f = usize::MAX;
        for pc in pcs {
            let (n, c) = self.by_pc[&pc];
            if let Some(i) = dis.at(pc) {
                if i.func != last_f {
                    s.push_str(&format!("<{}>\n", dis.funcs[i.func].name));
                    last_f = i.func;
                }
                s.push_str(&format!(
                    "{:>9.2} {:>8.2}  {:08x}  {} {}\n",
                    n as f64 / steps,
                    c as f64 / steps,
                    pc,
                    i.mnemonic,
                    i.operands
                ));
            }
        }
        s
    }
}

/// What one QEMU run measures: the machine, the core's timing table, the firmware's
/// summary line and the region whose per-instruction profile is kept.
struct RunSpec {
    machine: &'static str,
    cpu: &'static str,
    core: Core,
    summary_prefix: &'static str,
    profile_region: &'static str,
}

const M4F_RUN: RunSpec = RunSpec {
    machine: "netduinoplus2",
    cpu: "cortex-m4",
    core: Core::M4,
    summary_prefix: "ACIM-BENCH summary ",
    profile_region: "drive_step",
};

/// What a traced run measured: per-region statistics (marker overhead not subtracted),
/// the profile region's per-instruction profile, and the firmware's summary line.
type Measured = (HashMap<&'static str, Stat>, Profile, String);

/// How one QEMU run ended.
enum Traced {
    Done(Measured),
    /// A measured region executed this instruction, a branch into code the trace filter
    /// leaves out (the run was stopped).
    Left(String),
}

/// Traces the regions of `elf`: with the soft-float routines left out of the trace
/// filter when [`TraceFilter::narrowed`] allows it, else, or when a measured region turns
/// out to branch to them, with the whole call graph `graph`. The figures are the same
/// either way.
fn trace_regions(
    qemu: &Qemu,
    spec: &RunSpec,
    elf: &Path,
    dis: &Disassembly,
    graph: &Graph,
    markers: &HashMap<u32, Marker>,
    keep_trace: Option<&Path>,
) -> Res<Measured> {
    if let Some(narrow) = TraceFilter::narrowed(dis, graph) {
        match run_qemu(qemu, spec, elf, &narrow, dis, markers, keep_trace)? {
            Traced::Done(m) => return Ok(m),
            Traced::Left(what) => eprintln!(
                "a measured region executes `{what}`, a branch to a soft-float routine left out of the trace filter: tracing again with the whole call graph"
            ),
        }
    }
    match run_qemu(
        qemu,
        spec,
        elf,
        &TraceFilter::full(dis, graph),
        dis,
        markers,
        keep_trace,
    )? {
        Traced::Done(m) => Ok(m),
        Traced::Left(what) => Err(format!("{what}: left a filter that leaves nothing out")),
    }
}

/// One QEMU run of `elf` with the execution log restricted to `filter`, parsed as it
/// streams in: each executed instruction is weighted when the next PC (taken or not) is
/// known and counted when it lies between a region's begin and end markers.
fn run_qemu(
    qemu: &Qemu,
    spec: &RunSpec,
    elf: &Path,
    filter: &TraceFilter,
    dis: &Disassembly,
    markers: &HashMap<u32, Marker>,
    keep_trace: Option<&Path>,
) -> Res<Traced> {
    let started = Instant::now();
    let mut cmd = Command::new("qemu-system-arm");
    cmd.args([
        "-machine",
        spec.machine,
        "-cpu",
        spec.cpu,
        "-nographic",
        "-monitor",
        "none",
        "-serial",
        "none",
        "-semihosting-config",
        "enable=on,target=native",
        "-kernel",
    ])
    .arg(elf)
    .args(&qemu.one_insn_args)
    .args(["-d", "exec,nochain", "-dfilter", &filter.ranges])
    .stdin(Stdio::null())
    .stdout(Stdio::piped())
    .stderr(Stdio::piped());
    eprintln!(
        "running QEMU ({}) with the execution log ...",
        qemu.one_insn_args.join(" ")
    );
    let mut child = cmd.spawn().map_err(|e| format!("qemu-system-arm: {e}"))?;
    let mut stdout = child.stdout.take().ok_or("no stdout")?;
    let out_thread = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    let stderr = child.stderr.take().ok_or("no stderr")?;
    let mut reader = BufReader::with_capacity(
        1 << 20,
        BatchedPipe {
            inner: stderr,
            wait: false,
        },
    );
    let mut keep = match keep_trace {
        Some(p) => Some(std::io::BufWriter::new(
            std::fs::File::create(p).map_err(|e| format!("{}: {e}", p.display()))?,
        )),
        None => None,
    };

    // per instruction of the disassembly (dense, by index): its weights (decoded on its
    // first execution), the marker it is the entry of (index into `marker_list`), whether
    // it lies in a marker function, its executions and est. cycles in the profile region
    let n_insns = dis.insns.len();
    let mut weights: Vec<Option<Weights>> = vec![None; n_insns];
    let marker_list: Vec<Marker> = markers.values().copied().collect();
    let mut marker_of = vec![u8::MAX; n_insns];
    for (j, pc) in markers.keys().enumerate() {
        if let Some(k) = dis.index(*pc) {
            marker_of[k] = u8::try_from(j)
                .ok()
                .filter(|&j| j != u8::MAX)
                .ok_or("too many markers")?;
        }
    }
    let mut marker_ranges: Vec<(u32, u32)> = markers
        .values()
        .map(|m| (dis.funcs[m.func].start, dis.funcs[m.func].end))
        .collect();
    marker_ranges.sort();
    let in_marker = |pc: u32| marker_ranges.iter().any(|&(s, e)| s <= pc && pc < e);
    let in_marker_fn: Vec<bool> = dis.insns.iter().map(|i| in_marker(i.addr)).collect();
    let mut by_insn: Vec<(u64, u64)> = vec![(0, 0); n_insns];

    let mut stats: HashMap<&'static str, Stat> = HashMap::new();
    let mut active: Option<&'static str> = None;
    // the active region is the profiled one
    let mut profiling = false;
    let (mut count_i, mut count_c) = (0u64, 0u64);
    // the previous executed instruction, finalised when the next PC is known:
    // (pc, index in the disassembly, counted in a region)
    let mut pending: Option<(u32, usize, bool)> = None;
    let mut after_ls = false;
    let mut prev = Prev::default();
    let mut count_t = 0u64;
    let (mut count_down, mut count_up) = (0u64, 0u64);
    let mut unknown_pcs = 0u64;
    let (mut lines, mut counted_lines) = (0u64, 0u64);
    let mut other_lines = Vec::new();
    let mut stderr_summary = String::new();
    let mut line = Vec::with_capacity(256);

    loop {
        line.clear();
        let n = reader
            .read_until(b'\n', &mut line)
            .map_err(|e| format!("reading the QEMU log: {e}"))?;
        if n == 0 {
            break;
        }
        if let Some(k) = keep.as_mut() {
            use std::io::Write;
            let _ = k.write_all(&line);
        }
        if !line.starts_with(b"Trace ") {
            let l = String::from_utf8_lossy(&line);
            if let Some(sm) = l.trim().strip_prefix(spec.summary_prefix) {
                stderr_summary = sm.to_string();
            } else if other_lines.len() < 20 {
                other_lines.push(String::from_utf8_lossy(&line).trim().to_string());
            }
            continue;
        }
        let Some(pc) = trace_pc(&line) else {
            continue;
        };
        lines += 1;
        let k = dis.index(pc);

        // finalise the previous instruction now that its successor is known
        if let Some((ppc, pk, counted)) = pending.take() {
            let i = &dis.insns[pk];
            let w = weights[pk].get_or_insert_with(|| Weights::of(spec.core, i));
            let taken = pc != ppc + i.size;
            let t = w.table[taken as usize][after_ls as usize];
            after_ls = w.single_ls;
            let (c, next) = w.timing.step(taken, &prev);
            prev = next;
            if counted {
                count_c += c as u64;
                count_t += t as u64;
                let (d, u) = w.slack[taken as usize];
                count_down += d as u64;
                count_up += u as u64;
                if profiling {
                    let e = &mut by_insn[pk];
                    e.0 += 1;
                    e.1 += c as u64;
                }
            }
        }

        let marker = match k {
            Some(k) => marker_list.get(marker_of[k] as usize),
            None => markers.get(&pc),
        };
        if let Some(m) = marker {
            if m.begin {
                active = Some(m.region);
                profiling = m.region == spec.profile_region;
                count_i = 0;
                count_c = 0;
                count_t = 0;
                count_down = 0;
                count_up = 0;
            } else if active == Some(m.region) {
                stats
                    .entry(m.region)
                    .or_default()
                    .add(count_i, count_c, count_t);
                stats
                    .entry(m.region)
                    .or_default()
                    .add_slack(count_down, count_up);
                active = None;
                profiling = false;
            } else {
                active = None;
                profiling = false;
            }
            pending = k.map(|k| (pc, k, false));
            continue;
        }
        let counted = active.is_some()
            && !match k {
                Some(k) => in_marker_fn[k],
                None => in_marker(pc),
            };
        if counted {
            count_i += 1;
            counted_lines += 1;
            match k {
                None => unknown_pcs += 1,
                Some(k) if filter.leaves.get(k) == Some(&true) => {
                    let i = &dis.insns[k];
                    let what = format!(
                        "{} {} in {}",
                        i.mnemonic, i.operands, dis.funcs[i.func].name
                    );
                    let _ = child.kill();
                    let _ = child.wait();
                    let _ = out_thread.join();
                    return Ok(Traced::Left(what));
                }
                Some(_) => {}
            }
        }
        pending = k.map(|k| (pc, k, counted));
    }
    let status = child.wait().map_err(|e| e.to_string())?;
    let out = out_thread.join().unwrap_or_default();
    let summary = out
        .lines()
        .find_map(|l| l.strip_prefix(spec.summary_prefix))
        .map(str::to_string)
        .unwrap_or(stderr_summary);
    if !status.success() || summary.is_empty() {
        return Err(format!(
            "QEMU failed ({status}); firmware output:\n{out}\nother log lines: {other_lines:?}"
        ));
    }
    if unknown_pcs > 0 {
        eprintln!("warning: {unknown_pcs} executed PCs not found in the disassembly");
    }
    eprintln!(
        "  {} on {}: {lines} instructions logged, {counted_lines} in the measured regions ({}), {:.1} s",
        elf.file_name().unwrap_or_default().to_string_lossy(),
        spec.machine,
        if filter.leaves.is_empty() {
            "whole call graph"
        } else {
            "soft-float routines left out"
        },
        started.elapsed().as_secs_f64()
    );
    let profile = Profile {
        by_pc: by_insn
            .iter()
            .enumerate()
            .filter(|(_, e)| e.0 > 0)
            .map(|(k, &e)| (dis.insns[k].addr, e))
            .collect(),
    };
    Ok(Traced::Done((stats, profile, summary)))
}

// ------------------------------------------------------------------------------------
// static scan
// ------------------------------------------------------------------------------------

struct Findings {
    panics: Vec<String>,
    f64: Vec<String>,
    other_calls: Vec<String>,
    indirect: Vec<String>,
}

fn is_panic(name: &str) -> bool {
    let n = name.to_ascii_lowercase();
    n.contains("panic")
        || n.contains("unwrap_failed")
        || n.contains("expect_failed")
        || n.contains("slice_index")
        || n.contains("slice_start_index")
        || n.contains("slice_end_index")
        || n.contains("assert_failed")
        || n.contains("str_index")
}

fn is_f64(name: &str) -> bool {
    let n = name.trim_start_matches('_');
    (name.starts_with("__aeabi_d") && !name.starts_with("__aeabi_div"))
        || name.starts_with("__aeabi_f2d")
        || name.starts_with("__aeabi_i2d")
        || name.starts_with("__aeabi_ui2d")
        || name.starts_with("__aeabi_l2d")
        || name.starts_with("__aeabi_ul2d")
        || (name.starts_with("__")
            && (n.ends_with("df3")
                || n.ends_with("df2")
                || n.contains("dfsi")
                || n.contains("sidf")
                || n.contains("didf")
                || n.contains("dfdi")
                || n.contains("sfdf")
                || n.contains("dfsf")))
}

fn scan(dis: &Disassembly, g: &Graph) -> Findings {
    let mut f = Findings {
        panics: vec![],
        f64: vec![],
        other_calls: vec![],
        indirect: vec![],
    };
    for &k in &g.functions {
        let name = &dis.funcs[k].name;
        if is_panic(name) {
            f.panics.push(name.clone());
        } else if is_f64(name) {
            f.f64.push(name.clone());
        } else if name.starts_with("__") || name.contains("memcpy") || name.contains("memset") {
            f.other_calls.push(name.clone());
        }
    }
    // f64 arithmetic instructions (none exist on the single-precision FPU; listed if ever)
    for i in &dis.insns {
        if g.functions.contains(&i.func) && i.mnemonic.contains(".f64") {
            f.f64
                .push(format!("{} in {}", i.mnemonic, dis.funcs[i.func].name));
        }
    }
    for &k in &g.indirect {
        f.indirect.push(dis.funcs[k].name.clone());
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scenario on the host: the probed clone reproduces `Drive::step` bit for bit,
    /// the drive does not fault, and the three observers track the true speed.
    #[test]
    fn scenario_probed_step_matches_the_drive_on_the_host() {
        let s = scenario::run();
        assert_eq!(s.measured, scenario::MEASURED_STEPS, "{s:?}");
        assert_eq!(s.mismatches, 0, "{s:?}");
        assert_eq!(s.replica_faults, 0, "{s:?}");
        assert!(!s.drive_faulted, "{s:?}");
        assert_eq!(s.two_rate_measured, scenario::MEASURED_STEPS, "{s:?}");
        assert!(!s.two_rate_faulted, "{s:?}");
        // the steady loaded point: reached and held (500 rpm under 1.5 N m)
        assert_eq!(s.loaded_measured, scenario::LOADED_STEPS, "{s:?}");
        assert_eq!(s.two_rate_loaded_measured, scenario::LOADED_STEPS, "{s:?}");
        assert!(
            (s.loaded_true_rpm - scenario::SPEED_TARGET_RPM).abs() < 5.0,
            "{s:?}"
        );
        assert!(s.full_mean_abs_err_rpm < 10.0, "{s:?}");
        assert!(s.reduced_mean_abs_err_rpm < 10.0, "{s:?}");
        assert!(s.flux_mean_abs_err_rpm < 10.0, "{s:?}");
    }

    #[test]
    fn mnemonics_and_timings() {
        let mk = |m: &str, o: &str| Insn {
            addr: 0,
            size: 4,
            mnemonic: m.into(),
            operands: o.into(),
            func: 0,
        };
        assert_eq!(base_mnemonic("bls"), "b");
        assert_eq!(base_mnemonic("bl"), "bl");
        assert_eq!(base_mnemonic("vmovgt.f32"), "vmov");
        assert_eq!(base_mnemonic("movs"), "mov");
        assert_eq!(base_mnemonic("ldr.w"), "ldr");
        assert_eq!(base_mnemonic("vmls.f32"), "vmls");
        assert_eq!(cycles(&mk("vdiv.f32", "s0, s1, s2"), false, false).0, 14);
        assert_eq!(cycles(&mk("vfma.f32", "s0, s1, s2"), false, false).0, 3);
        assert_eq!(cycles(&mk("pop", "{r4, r5, r6, r7, pc}"), true, false).0, 8);
        assert_eq!(
            cycles(&mk("push", "{r4, r5, r6, r7, lr}"), false, false).0,
            6
        );
        assert_eq!(cycles(&mk("vpush", "{d8, d9}"), false, false).0, 5);
        assert_eq!(cycles(&mk("ldr", "r0, [r1]"), false, true).0, 1);
        assert_eq!(cycles(&mk("ldr", "r0, [r1]"), false, false).0, 2);
        assert_eq!(cycles(&mk("bne", "0x8000"), true, false).0, 3);
        assert_eq!(cycles(&mk("bne", "0x8000"), false, false).0, 1);
        assert_eq!(cycles(&mk("vmov", "r0, r1, d0"), false, false).0, 2);
        assert_eq!(cycles(&mk("vmov", "s0, r1"), false, false).0, 1);
        assert!(is_f64("__aeabi_dadd") && is_f64("__adddf3") && is_f64("__extendsfdf2"));
        assert!(!is_f64("__aeabi_uidiv") && !is_f64("__aeabi_memcpy"));
        assert!(is_panic("core::panicking::panic_bounds_check::h1"));
    }

    /// Cycles of a straight-line sequence (no branches) under the pipeline model.
    fn seq(core: Core, code: &[(&str, &str)]) -> u32 {
        let mut prev = Prev::default();
        let mut total = 0;
        for (m, o) in code {
            let i = Insn {
                addr: 0,
                size: 4,
                mnemonic: m.to_string(),
                operands: o.to_string(),
                func: 0,
            };
            let (c, _, next) = timed(core, &i, false, &prev);
            prev = next;
            total += c;
        }
        total
    }

    /// The load/store examples of the Cortex-M4 TRM (r0p1, 3.3.2 "Load/store timings"),
    /// with the totals the TRM states, and the rules they illustrate.
    #[test]
    fn load_store_pipelining_matches_the_trm_examples() {
        // "LDR R0,[R1]; LDR R1,[R2] - normally three cycles total"
        assert_eq!(
            seq(Core::M4, &[("ldr", "r0, [r1]"), ("ldr", "r1, [r2]")]),
            3
        );
        // "LDR R0,[R1,R2]; STR R1,[R3,R4] - normally three cycles total"
        assert_eq!(
            seq(
                Core::M4,
                &[("ldr", "r0, [r1, r2]"), ("str", "r1, [r3, r4]")]
            ),
            3
        );
        // "LDR R0,[R1,R2]!; LDR R1,[R3,#4]; LDR R4,[R5],#4; STR R6,[R7,#8] - normally
        // five cycles total"
        assert_eq!(
            seq(
                Core::M4,
                &[
                    ("ldr", "r0, [r1, r2]!"),
                    ("ldr", "r1, [r3, #4]"),
                    ("ldr", "r4, [r5], #4"),
                    ("str", "r6, [r7, #8]"),
                ]
            ),
            5
        );
        // the first load's destination forms the second one's address: not pipelined
        assert_eq!(
            seq(Core::M4, &[("ldr", "r0, [r1]"), ("ldr", "r2, [r0, #4]")]),
            4
        );
        // "STR Rx,[Ry,#imm] is always one cycle"; nothing pipelines after a store
        assert_eq!(seq(Core::M4, &[("str", "r0, [r1, #4]")]), 1);
        assert_eq!(
            seq(Core::M4, &[("str", "r0, [r1]"), ("ldr", "r2, [r3]")]),
            3
        );
        assert_eq!(seq(Core::M4, &[("str", "r0, [r1, r2]")]), 2);
        // LDRD is not pipelined with its neighbours: 3
        assert_eq!(
            seq(Core::M4, &[("ldr", "r0, [r1]"), ("ldrd", "r2, r3, [r4]")]),
            5
        );
    }

    /// FP timings: TRM table 7-1 for issue costs, GCC's Cortex-M4 FPU pipeline
    /// description for the result latencies (VADD/VMUL/VCVT 2, multiply-accumulate 4,
    /// forwarded to a following accumulate's addend).
    #[test]
    fn fpu_result_use_stalls_and_core_moves() {
        // independent: 1 + 1
        assert_eq!(
            seq(
                Core::M4,
                &[("vmul.f32", "s0, s1, s2"), ("vadd.f32", "s3, s5, s4")]
            ),
            2
        );
        // dependent: the VADD waits one cycle for s0
        assert_eq!(
            seq(
                Core::M4,
                &[("vmul.f32", "s0, s1, s2"), ("vadd.f32", "s3, s0, s4")]
            ),
            3
        );
        // a VMUL result as the addend of the next VMLA is forwarded: 1 + 3
        assert_eq!(
            seq(
                Core::M4,
                &[("vmul.f32", "s0, s1, s2"), ("vmla.f32", "s0, s3, s4")]
            ),
            4
        );
        // as a multiplicand it is not: 1 + 1 + 3
        assert_eq!(
            seq(
                Core::M4,
                &[("vmul.f32", "s0, s1, s2"), ("vmla.f32", "s3, s0, s4")]
            ),
            5
        );
        // a VMLA result used next: 3 + 1 + 1; a VABS result: no extra latency
        assert_eq!(
            seq(
                Core::M4,
                &[("vmla.f32", "s0, s1, s2"), ("vstr", "s0, [r0]")]
            ),
            3 + 1 + 2
        );
        assert_eq!(
            seq(
                Core::M4,
                &[("vabs.f32", "s0, s1"), ("vadd.f32", "s2, s0, s0")]
            ),
            2
        );
        // VLDR then use: 2 + 1 (no extra latency); compare then flags: 1 + 1
        assert_eq!(
            seq(
                Core::M4,
                &[("vldr", "s0, [r0]"), ("vadd.f32", "s1, s0, s0")]
            ),
            3
        );
        assert_eq!(
            seq(
                Core::M4,
                &[("vcmp.f32", "s0, s1"), ("vmrs", "APSR_nzcv, fpscr")]
            ),
            2
        );
        // one float to/from a core register: 2 each; between S registers: 1
        assert_eq!(seq(Core::M4, &[("vmov", "s0, r0")]), 2);
        assert_eq!(seq(Core::M4, &[("vmov", "r0, s0")]), 2);
        assert_eq!(seq(Core::M4, &[("vmov.f32", "s0, s1")]), 1);
        assert_eq!(seq(Core::M4, &[("vmov", "r0, r1, d0")]), 2);
        // a D register names two singles
        assert_eq!(
            seq(
                Core::M4,
                &[("vadd.f32", "s1, s2, s3"), ("vstr", "d0, [r0]")]
            ),
            1 + 2 + 1
        );
        // the M3 long multiplies: worst case of the TRM's early-terminating ranges
        assert_eq!(seq(Core::M3, &[("smull", "r0, r1, r2, r3")]), 5);
        assert_eq!(seq(Core::M3, &[("smlal", "r0, r1, r2, r3")]), 7);
        assert_eq!(seq(Core::M4, &[("smlal", "r0, r1, r2, r3")]), 1);
        // what the model leaves open: refills 1-3 (2 taken), division overlap, M3 early
        // termination
        let mk = |m: &str, o: &str| Insn {
            addr: 0,
            size: 2,
            mnemonic: m.into(),
            operands: o.into(),
            func: 0,
        };
        assert_eq!(slack(Core::M4, &mk("bne", "0x8000"), true), (1, 1));
        assert_eq!(slack(Core::M4, &mk("bne", "0x8000"), false), (0, 0));
        assert_eq!(slack(Core::M4, &mk("pop", "{r4, pc}"), true), (1, 1));
        assert_eq!(
            slack(Core::M4, &mk("vdiv.f32", "s0, s1, s2"), false),
            (13, 0)
        );
        assert_eq!(
            slack(Core::M3, &mk("smlal", "r0, r1, r2, r3"), false),
            (2, 0)
        );
        assert_eq!(
            slack(Core::M4, &mk("smlal", "r0, r1, r2, r3"), false),
            (0, 0)
        );
    }
}
