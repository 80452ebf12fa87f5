//! `acim-monitor`: the live monitor (see the crate documentation and the README's "Watch
//! it live").
use acim_monitor::app::App;
use acim_monitor::link::{Event, Link, Source};
use acim_monitor::record::Recorder;
use acim_monitor::{script, ui};
use ratatui::crossterm::event::{self, Event as TermEvent, KeyCode, KeyEventKind, KeyModifiers};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

const USAGE: &str = "usage: acim-monitor (--tcp ADDR | --serial PATH [--baud N]) [--record FILE] [--window S] [--rate N]
                    [--headless --until S [--script FILE] [--screenshot FILE] [--size WxH] [--timeout S]]
  --tcp ADDR         the virtual board (acim-sim serve) or any TCP bridge, e.g. 127.0.0.1:7878
  --serial PATH      the board's UART, e.g. /dev/ttyACM0 (--baud, default 115200)
  --record FILE      record every sample to a CSV file (also :record FILE at run time)
  --window S         seconds of board time in the plots (default 10)
  --rate N           ask the board for a sample every N control periods (protocol 1;
                     default 500, 10 Hz; the firmware's UART carries about 90 samples/s,
                     a rate of 56)
  --headless         no terminal: run --script against the board until --until seconds
                     of board time after the first sample, then write --screenshot (the
                     screen as text, --size, default 160x48); fails after --timeout
                     wall-clock seconds (default 60)
keys: type a board command and Enter; Up/Down history; Esc sends stop; Ctrl-C quits; F1 or :help;
      PgUp/PgDn scroll the replies, Home the oldest, End the newest
the terminal: 80x24 at least (speed, currents, torque); 120x40 and up shows all seven charts";

struct Opts {
    source: Source,
    record: Option<PathBuf>,
    window: f64,
    rate: Option<u16>,
    headless: bool,
    until: Option<f64>,
    script: Option<PathBuf>,
    screenshot: Option<PathBuf>,
    size: (u16, u16),
    timeout: f64,
}

fn parse_args(args: &[String]) -> Result<Opts, String> {
    let mut tcp = None;
    let mut serial = None;
    let mut baud = acim_firmware_core::board::UART_BAUD;
    let mut o = Opts {
        source: Source::Tcp(String::new()),
        record: None,
        window: 10.0,
        rate: None,
        headless: false,
        until: None,
        script: None,
        screenshot: None,
        size: (160, 48),
        timeout: 60.0,
    };
    let mut it = args.iter();
    let num = |v: &str, what: &str| -> Result<f64, String> {
        v.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite() && *x > 0.0)
            .ok_or_else(|| format!("{what} takes a positive number, got {v:?}"))
    };
    while let Some(a) = it.next() {
        let mut val = || {
            it.next()
                .cloned()
                .ok_or_else(|| format!("{a} needs a value\n{USAGE}"))
        };
        match a.as_str() {
            "--tcp" => tcp = Some(val()?),
            "--serial" => serial = Some(val()?),
            "--baud" => {
                let v = val()?;
                baud = v
                    .parse()
                    .map_err(|_| format!("--baud takes a whole number, got {v:?}"))?
            }
            "--record" => o.record = Some(PathBuf::from(val()?)),
            "--window" => o.window = num(&val()?, "--window")?,
            "--rate" => {
                let v = val()?;
                let (lo, hi) = (
                    acim_firmware_core::protocol::MIN_RATE_PERIODS,
                    acim_firmware_core::protocol::MAX_RATE_PERIODS,
                );
                o.rate = Some(
                    v.parse::<u16>()
                        .ok()
                        .filter(|n| (lo..=hi).contains(n))
                        .ok_or_else(|| {
                            format!("--rate takes {lo}..={hi} control periods, got {v:?}")
                        })?,
                );
            }
            "--headless" => o.headless = true,
            "--until" => o.until = Some(num(&val()?, "--until")?),
            "--script" => o.script = Some(PathBuf::from(val()?)),
            "--screenshot" => o.screenshot = Some(PathBuf::from(val()?)),
            "--timeout" => o.timeout = num(&val()?, "--timeout")?,
            "--size" => {
                let v = val()?;
                o.size = v
                    .split_once('x')
                    .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                    .filter(|&(w, h): &(u16, u16)| {
                        (40..=1000).contains(&w) && (12..=1000).contains(&h)
                    })
                    .ok_or_else(|| format!("--size takes WxH (e.g. 160x48), got {v:?}"))?;
            }
            "-h" | "--help" => return Err(USAGE.to_string()),
            other => return Err(format!("unknown option {other:?}\n{USAGE}")),
        }
    }
    o.source = match (tcp, serial) {
        (Some(t), None) => Source::Tcp(t),
        (None, Some(s)) => Source::Serial(s, baud),
        _ => return Err(format!("give exactly one of --tcp and --serial\n{USAGE}")),
    };
    if o.headless && o.until.is_none() {
        return Err("--headless needs --until S (board time to stop at)".into());
    }
    if !o.headless && (o.until.is_some() || o.script.is_some() || o.screenshot.is_some()) {
        return Err("--until, --script and --screenshot are for --headless".into());
    }
    Ok(o)
}

fn start(o: &Opts) -> Result<(App, Link), String> {
    let mut app = App::new(o.source.to_string());
    app.window_s = o.window;
    if let Some(p) = &o.record {
        app.recorder = Some(
            Recorder::create(p.clone())
                .map_err(|e| format!("cannot record to {}: {e}", p.display()))?,
        );
    }
    let link = Link::spawn(o.source.clone());
    // telemetry on (repeated after every reconnection) and the parameters for the panel
    if let Some(n) = o.rate {
        link.send(&format!("rate {n}"));
    }
    link.send("stream on");
    link.send("get");
    Ok((app, link))
}

fn headless(o: &Opts) -> Result<(), String> {
    let steps = match &o.script {
        Some(p) => script::parse(
            &std::fs::read_to_string(p).map_err(|e| format!("cannot read {}: {e}", p.display()))?,
        )?,
        None => Vec::new(),
    };
    let until = o.until.unwrap_or(0.0);
    let (mut app, link) = start(o)?;
    let t0 = Instant::now();
    let mut next = 0;
    let mut last_flush = Instant::now();
    // script times count from the first sample received
    let mut first: Option<f64> = None;
    loop {
        if let Some(ev) = link.event_timeout(App::POLL) {
            app.on_event(ev);
        }
        app.tick(Instant::now());
        let board_time = app.last().map(|r| r.time_s);
        if first.is_none() {
            first = board_time;
        }
        let now = board_time.zip(first).map(|(t, f)| t - f);
        while let (Some(now), Some(s)) = (now, steps.get(next)) {
            if now < s.at_s {
                break;
            }
            if let Some(c) = app.command(&s.command) {
                link.send(&c);
            }
            next += 1;
        }
        if last_flush.elapsed() > Duration::from_millis(500) {
            app.flush();
            last_flush = Instant::now();
        }
        if now.is_some_and(|t| t >= until) && next >= steps.len() {
            break;
        }
        if t0.elapsed().as_secs_f64() > o.timeout {
            return Err(format!(
                "timed out after {} s at board time {:?} ({} of {} script steps sent)",
                o.timeout,
                now,
                next,
                steps.len()
            ));
        }
    }
    // the replies to the last commands, but no telemetry beyond --until (a board running
    // faster than real time has sent more meanwhile)
    let settle = Instant::now();
    while settle.elapsed() < Duration::from_millis(200) {
        match link.event_timeout(App::POLL) {
            // a `$X` still completes the last sample before --until
            Some(Event::Telemetry(_)) | None => {}
            Some(ev) => app.on_event(ev),
        }
    }
    if let Some(p) = &o.screenshot {
        let text = ui::screenshot(&app, o.size.0, o.size.1);
        std::fs::write(p, text).map_err(|e| format!("cannot write {}: {e}", p.display()))?;
    }
    app.flush_pending();
    let rows = app.recorder.as_ref().map_or(0, |r| r.rows());
    if let Some(r) = app.recorder.take() {
        r.finish().map_err(|e| format!("recording: {e}"))?;
    }
    let errors = app.messages.iter().filter(|m| m.error).count();
    println!(
        "board time {:.3} s, {} frames, {} rows recorded, {} bad frames, {} missed samples, {} reconnects, {} error lines",
        app.last().map_or(0.0, |r| r.time_s),
        app.frames,
        rows,
        app.bad_frames,
        app.missed,
        app.reconnects,
        errors
    );
    Ok(())
}

fn interactive(o: &Opts) -> Result<(), String> {
    let (mut app, link) = start(o)?;
    let mut term = ratatui::init();
    let mut last_flush = Instant::now();
    let result = loop {
        while let Some(ev) = link.try_event() {
            app.on_event(ev);
        }
        app.tick(Instant::now());
        if let Err(e) = term.draw(|f| ui::render(f, &app)) {
            break Err(format!("terminal: {e}"));
        }
        match event::poll(App::POLL) {
            Ok(true) => {
                if let Ok(TermEvent::Key(k)) = event::read() {
                    if k.kind != KeyEventKind::Press {
                        continue;
                    }
                    let ctrl = k.modifiers.contains(KeyModifiers::CONTROL);
                    match k.code {
                        KeyCode::Char('c') | KeyCode::Char('q') if ctrl => app.quit = true,
                        KeyCode::Esc => link.send("stop"),
                        KeyCode::F(1) => {
                            app.command(":help");
                        }
                        KeyCode::Enter => {
                            if let Some(c) = app.submit() {
                                link.send(&c);
                            }
                        }
                        KeyCode::PageUp => app.scroll_replies(app.reply_page()),
                        KeyCode::PageDown => app.scroll_replies(-app.reply_page()),
                        KeyCode::Home => app.replies_oldest(),
                        KeyCode::End => app.replies_newest(),
                        KeyCode::Backspace => {
                            app.input.pop();
                        }
                        KeyCode::Up if !app.history.is_empty() => {
                            let p = app
                                .history_pos
                                .map_or(app.history.len() - 1, |p| p.saturating_sub(1));
                            app.history_pos = Some(p);
                            app.input = app.history[p].clone();
                        }
                        KeyCode::Down => match app.history_pos {
                            Some(p) if p + 1 < app.history.len() => {
                                app.history_pos = Some(p + 1);
                                app.input = app.history[p + 1].clone();
                            }
                            _ => {
                                app.history_pos = None;
                                app.input.clear();
                            }
                        },
                        KeyCode::Char(c) if !ctrl && app.input.len() < 120 => app.input.push(c),
                        _ => {}
                    }
                }
            }
            Ok(false) => {}
            Err(e) => break Err(format!("terminal: {e}")),
        }
        if last_flush.elapsed() > Duration::from_millis(500) {
            app.flush();
            last_flush = Instant::now();
        }
        if app.quit {
            break Ok(());
        }
    };
    ratatui::restore();
    app.flush_pending();
    if let Some(r) = app.recorder.take() {
        let rows = r.rows();
        let p = r.finish().map_err(|e| format!("recording: {e}"))?;
        println!("recorded {rows} rows to {}", p.display());
    }
    result
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let o = match parse_args(&args) {
        Ok(o) => o,
        Err(e) => {
            eprintln!("acim-monitor: {e}");
            return ExitCode::from(2);
        }
    };
    let r = if o.headless {
        headless(&o)
    } else {
        interactive(&o)
    };
    match r {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("acim-monitor: {e}");
            ExitCode::FAILURE
        }
    }
}
