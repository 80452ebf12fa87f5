//! End to end, as a person uses it: the virtual board on a local port, the monitor binary
//! connected to it running start -> speed step -> load step -> stop (with bad commands in
//! between and a cable pull in the middle), recording to CSV. The recording must equal
//! the board's own trace of the same run (its command log replayed through the firmware's
//! ControlLoop + SimulatedStage) sample for sample, at the telemetry's resolution; the
//! captured screen must show every chart.

use acim_firmware_core::protocol::{decode_extension, encode_extension};
use acim_firmware_core::telemetry::{decode, encode};
use acim_vboard::board::{replay, Event};
use acim_vboard::server::{self, Options, Pace};
use std::collections::BTreeMap;
use std::net::TcpListener;
use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

const SCRIPT: &str = "\
# board seconds after the first sample, command
0.2 start
0.3 frobnicate
0.4 speed 5000
0.5 speed 500
0.6 set limits.current_limit 99
2.5 load 1.5
4.0 stop
4.8 frobnicate
4.9 speed 5000
5.0 set limits.current_limit 99
";

fn out_dir() -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("acim-monitor-e2e");
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn start_speed_load_stop_recorded_as_the_board_ran_it() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let srv = server::start(
        listener,
        Options {
            pace: Pace::Factor(10.0),
            rate: Some(50),
        },
    )
    .unwrap();
    let dir = out_dir();
    let (script, csv, screen) = (
        dir.join("script.txt"),
        dir.join("run.csv"),
        dir.join("screen.txt"),
    );
    std::fs::write(&script, SCRIPT).unwrap();
    let child = Command::new(env!("CARGO_BIN_EXE_acim-monitor"))
        .arg("--tcp")
        .arg(srv.local_addr().to_string())
        .args([
            "--headless",
            "--until",
            "5.5",
            "--timeout",
            "60",
            "--script",
        ])
        .arg(&script)
        .arg("--record")
        .arg(&csv)
        .arg("--screenshot")
        .arg(&screen)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();

    // a cable pull once the load step has been applied
    let t0 = Instant::now();
    while !srv.log().iter().any(|l| {
        matches!(
            l.event,
            Event::Control(acim_firmware_core::control::ControlCommand::PlantLoad(_))
        )
    }) {
        assert!(t0.elapsed() < Duration::from_secs(60), "no load step seen");
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(30));
    srv.disconnect_all();

    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(out.status.success(), "monitor failed: {stdout}");
    assert!(stdout.contains(" 1 reconnects"), "{stdout}");
    assert!(stdout.contains(" 0 bad frames"), "{stdout}");
    let log = srv.log();
    srv.shutdown();

    // the recording
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(acim_monitor::record::HEADER));
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert!(rows.len() > 300, "{} rows", rows.len());
    let last_period: u64 = rows.last().unwrap()[2].parse().unwrap();

    // the board's own trace of the same run
    let reference: BTreeMap<u32, _> = replay(&log, last_period + 1)
        .into_iter()
        .map(|s| (s.t.seq, s))
        .collect();
    let mut seqs = Vec::new();
    for r in &rows {
        let seq: u32 = r[1].parse().unwrap();
        seqs.push(seq);
        let s = reference
            .get(&seq)
            .unwrap_or_else(|| panic!("seq {seq} not in the trace"));
        // the frame's resolution: what encode/decode leaves of the board's values
        let t = decode(&encode(&s.t)).unwrap();
        let x = decode_extension(&encode_extension(&s.x)).unwrap();
        let f = |i: usize| r[i].parse::<f32>().unwrap();
        assert_eq!(r[2].parse::<u32>().unwrap(), s.x.period, "seq {seq}");
        assert_eq!(r[3].parse::<u8>().unwrap(), t.state, "seq {seq}");
        assert_eq!(r[4].parse::<u8>().unwrap(), t.fault, "seq {seq}");
        let want = [
            t.speed_ref_rpm,
            t.speed_est_rpm,
            t.plant_speed_rpm,
            t.i_d,
            t.i_q,
            x.i_d_ref,
            x.i_q_ref,
            t.torque,
            t.load_torque,
            t.rs,
            t.flux,
            t.dc_bus,
        ];
        for (k, w) in want.iter().enumerate() {
            let got = f(5 + k);
            // the CSV prints f32 in its shortest round-trip form: equal, not close
            assert_eq!(got, *w, "seq {seq} column {}", 5 + k);
        }
    }
    // in order, each once; the samples sent while the cable was out are the only gap
    assert!(seqs.windows(2).all(|w| w[0] < w[1]));
    let gaps = seqs.windows(2).filter(|w| w[1] != w[0] + 1).count();
    assert_eq!(gaps, 1, "one gap (the cable pull)");
    // the gap is the outage: the monitor's 100 ms backoff plus its reconnection, at the
    // board's 10x pace and 50 samples/s (500 samples per wall second); allow half a wall
    // second in all, for a loaded 2-core machine (0.1-0.25 s seen)
    let span = (seqs.last().unwrap() - seqs[0] + 1) as usize;
    let lost = span - seqs.len();
    assert!(
        (20..=250).contains(&lost),
        "{lost} samples lost in the outage ({} of {span} recorded)",
        seqs.len()
    );

    // the run did what the script asked
    let col = |r: &Vec<&str>, i: usize| r[i].parse::<f32>().unwrap();
    let running: Vec<_> = rows.iter().filter(|r| r[3] == "2").collect();
    assert!(!running.is_empty());
    assert!(
        running
            .iter()
            .any(|r| (col(r, 7) - 500.0).abs() < 10.0 && col(r, 13).abs() < 0.1),
        "500 rpm reached before the load step"
    );
    assert!(
        running.iter().any(|r| (col(r, 13) - 1.5).abs() < 0.1),
        "the load estimate found the 1.5 N m step"
    );
    assert_eq!(rows.last().unwrap()[3], "0", "idle after stop");
    // the refused commands reached no event: the log holds only what was accepted
    let cmds: Vec<_> = log
        .iter()
        .filter(|l| matches!(l.event, Event::Control(_)))
        .collect();
    assert_eq!(cmds.len(), 4, "start, speed 500, load 1.5, stop: {cmds:?}");
    assert!(!log.iter().any(|l| matches!(l.event, Event::Settings(_))));

    // the captured screen
    let screen = std::fs::read_to_string(&screen).unwrap();
    for s in [
        "Speed [rpm]",
        "reference",
        "estimate",
        "true (model)",
        "Currents d/q [A]",
        "i_d ref",
        "i_q ref",
        "Rotor flux [Wb]",
        "Rs estimate [ohm]",
        "Torque [N m]",
        "load estimate",
        "DC bus [V]",
        // the virtual board times its step on the host
        "Host step time [us] (virtual board)",
        "t [s]",
        "state Idle",
        "reconnects 1",
        "err unknown command (try help)",
        "err out of range",
        "err (limits.overcurrent_trip:",
        "limits.current_limit 4.67 A",
        "> set limits.current_limit 99",
    ] {
        assert!(screen.contains(s), "screen lacks {s:?}:\n{screen}");
    }
    let braille = screen
        .chars()
        .filter(|c| ('\u{2801}'..='\u{28ff}').contains(c))
        .count();
    assert!(braille > 500, "{braille} plot cells:\n{screen}");
    assert_eq!(screen.lines().count(), 48);
}
