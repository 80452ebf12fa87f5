//! The README's screenshots, reproducibly: the virtual board's run (start, speed 500, a
//! refused setting, load 1.5 N m, stop) fed through the monitor's own event handling and
//! screen, untimed (the host-step-time chart reads 0: a live board fills it) and without
//! the network, so the same command always draws the same screens: 200 x 50 characters
//! (the full layout) and 80 x 24 (the smallest supported terminal, the compact layout).
//! CI diffs them against docs/monitor-screen.txt and docs/monitor-screen-80x24.txt; the
//! end-to-end test checks the live screen.
//!
//!   cargo run -p acim-monitor --example screenshot -- docs/monitor-screen.txt docs/monitor-screen-80x24.txt
//!
//! Without the second path, the 80 x 24 screen goes next to the first with `-80x24`
//! before its extension.

use acim_firmware_core::board::PWM_FREQUENCY_HZ;
use acim_monitor::app::App;
use acim_monitor::link::{decode_line, Event};
use acim_vboard::board::{Board, BOARD_NAME};

fn main() -> Result<(), String> {
    let mut args = std::env::args().skip(1);
    let usage = "usage: screenshot <200x50 output file> [<80x24 output file>]";
    let large = args.next().ok_or(usage)?;
    let small = match args.next() {
        Some(p) => p,
        None => {
            let p = std::path::Path::new(&large);
            let stem = p.file_stem().ok_or(usage)?.to_string_lossy();
            let name = match p.extension() {
                Some(e) => format!("{stem}-80x24.{}", e.to_string_lossy()),
                None => format!("{stem}-80x24"),
            };
            p.with_file_name(name).to_string_lossy().into_owned()
        }
    };
    if args.next().is_some() {
        return Err(usage.into());
    }
    let mut board = Board::new(false);
    let mut app = App::new("tcp 127.0.0.1:7878".into());
    app.window_s = 6.0;
    app.on_event(Event::Connected);
    app.on_event(Event::Hello {
        version: 1,
        pwm_hz: PWM_FREQUENCY_HZ,
        board: BOARD_NAME.into(),
    });
    let hz = PWM_FREQUENCY_HZ as f64;
    let schedule: &[(f64, &str)] = &[
        (0.0, "rate 50"),
        (0.0, "stream on"),
        (0.0, "get"),
        (0.2, "start"),
        (0.5, "speed 500"),
        (2.0, "set limits.current_limit 99"),
        (2.5, "load 1.5"),
        (4.0, "frobnicate"),
        (4.2, "speed 5000"),
        (4.5, "stop"),
    ];
    let mut stream = false;
    let mut next = 0;
    while board.period() < (5.5 * hz) as u64 {
        while let Some((t, cmd)) = schedule.get(next) {
            if (board.period() as f64) < t * hz {
                break;
            }
            app.on_event(Event::Sent(cmd.to_string()));
            for l in board.handle_line(cmd.as_bytes(), &mut stream) {
                app.on_event(decode_line(
                    String::from_utf8_lossy(&l).trim_end().as_bytes(),
                ));
            }
            next += 1;
        }
        if let Some(s) = board.step() {
            if stream {
                for l in String::from_utf8_lossy(&s.encode()).lines() {
                    app.on_event(decode_line(l.as_bytes()));
                }
            }
        }
    }
    for (out, (w, h)) in [(&large, (200, 50)), (&small, (80, 24))] {
        let text = acim_monitor::ui::screenshot(&app, w, h);
        std::fs::write(out, &text).map_err(|e| format!("cannot write {out}: {e}"))?;
        println!("wrote {out} ({w}x{h})");
    }
    Ok(())
}
