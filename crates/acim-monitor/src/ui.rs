//! The screen. [`render`] draws the [`App`]; [`screenshot`] renders it into ratatui's test
//! backend and returns the screen as text (what CI checks and the README shows).
//!
//! Three layouts, by the terminal's size:
//!
//! - **full** ([`FULL_WIDTH`] x [`FULL_HEIGHT`] and larger): two status lines, seven live
//!   charts (speed, d/q currents, rotor flux, Rs estimate, torque, DC bus, interrupt
//!   time) and the drive's readout with the parameters, the board's replies and the
//!   command line; each chart's title is its legend, every series' name in its colour
//!   with its latest value;
//! - **compact** (from the minimum, [`MIN_WIDTH`] x [`MIN_HEIGHT`], up to the full
//!   layout): the three charts that matter most (speed, currents, torque) and the readout
//!   (flux, Rs, bus, interrupt time) in a 2 x 2 grid, each chart's legend on its lower
//!   border (short names: `ref`, `est`, `true`; `d`, `q` and their references `d*`,
//!   `q*`), the time axis unlabelled (the plots span the last `:window` seconds of board
//!   time: `window` on the second status line);
//! - **too small** (below the minimum): the status line (drive state and fault first)
//!   and a banner asking for a larger terminal; the keys still work.
//!
//! The status line puts the drive state and the fault first, so a narrow terminal cuts
//! the rest. The replies are wrapped, never cut (continuation lines indented by two
//! spaces), and scroll: PgUp/PgDn a page, Home the oldest, End the newest
//! ([`App::scroll_replies`]). Values that are not fresh ([`App::held`]) are drawn dim
//! grey, and the charts and the readout they are in name the reason (`held: link down`,
//! `held: commissioning`, ...). Quantities that cannot be negative (flux, resistance,
//! bus voltage, interrupt time) are plotted from 0 at the lowest, never on a negative
//! axis. On the virtual board ([`App::is_virtual_board`]) the interrupt-time chart is the
//! host's step time in microseconds: that board measures its control step on the host,
//! not in MCU cycles.

use crate::app::{App, Held, LinkState, Row};
use acim_firmware_core::board::SYSCLK_HZ;
use ratatui::backend::TestBackend;
use ratatui::layout::{Alignment, Constraint, Direction, Flex, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType, Paragraph, Wrap};
use ratatui::{Frame, Terminal};

/// The smallest terminal the monitor draws its layout in, columns.
pub const MIN_WIDTH: u16 = 80;
/// The smallest terminal the monitor draws its layout in, rows.
pub const MIN_HEIGHT: u16 = 24;
/// From this many columns (and [`FULL_HEIGHT`] rows) the full layout: all seven charts.
pub const FULL_WIDTH: u16 = 120;
/// From this many rows (and [`FULL_WIDTH`] columns) the full layout: all seven charts.
pub const FULL_HEIGHT: u16 = 40;

/// One plotted quantity.
struct Series {
    /// Its name in the full layout's legend.
    name: &'static str,
    /// Its name in the compact layout's legend.
    short: &'static str,
    color: Color,
    /// Its value in a sample, in the chart's unit.
    get: fn(&Row) -> Option<f64>,
    /// One of the drive's own estimates or measurements, which hold their last values
    /// while the drive is switched off, tripped or commissioning (false: the board's,
    /// always live).
    drive: bool,
}

/// One chart.
struct Spec {
    /// The title, with the unit.
    title: &'static str,
    /// The compact layout's title (a chart there is 40 columns wide).
    short_title: &'static str,
    series: &'static [Series],
    /// The quantity cannot be negative: the axis starts at 0 at the lowest.
    nonneg: bool,
}

const SPEED: Spec = Spec {
    title: "Speed [rpm]",
    short_title: "Speed [rpm]",
    series: &[
        Series {
            name: "reference",
            short: "ref",
            color: Color::Yellow,
            get: |r| Some(r.t.speed_ref_rpm as f64),
            drive: true,
        },
        Series {
            name: "estimate",
            short: "est",
            color: Color::Cyan,
            get: |r| Some(r.t.speed_est_rpm as f64),
            drive: true,
        },
        Series {
            name: "true (model)",
            short: "true",
            color: Color::Green,
            get: |r| Some(r.t.plant_speed_rpm as f64),
            drive: false,
        },
    ],
    nonneg: false,
};
const CURRENTS: Spec = Spec {
    title: "Currents d/q [A]",
    short_title: "Currents [A]",
    series: &[
        Series {
            name: "i_d",
            short: "d",
            color: Color::Cyan,
            get: |r| Some(r.t.i_d as f64),
            drive: true,
        },
        Series {
            name: "i_q",
            short: "q",
            color: Color::Magenta,
            get: |r| Some(r.t.i_q as f64),
            drive: true,
        },
        Series {
            name: "i_d ref",
            short: "d*",
            color: Color::Blue,
            get: |r| r.x.map(|x| x.i_d_ref as f64),
            drive: true,
        },
        Series {
            name: "i_q ref",
            short: "q*",
            color: Color::Red,
            get: |r| r.x.map(|x| x.i_q_ref as f64),
            drive: true,
        },
    ],
    nonneg: false,
};
const FLUX: Spec = Spec {
    title: "Rotor flux [Wb]",
    short_title: "Flux [Wb]",
    series: &[Series {
        name: "model flux",
        short: "flux",
        color: Color::Cyan,
        get: |r| Some(r.t.flux as f64),
        drive: true,
    }],
    nonneg: true,
};
const RS: Spec = Spec {
    title: "Rs estimate [ohm]",
    short_title: "Rs [ohm]",
    series: &[Series {
        name: "Rs estimate",
        short: "Rs",
        color: Color::Yellow,
        get: |r| Some(r.t.rs as f64),
        drive: true,
    }],
    nonneg: true,
};
const TORQUE: Spec = Spec {
    title: "Torque [N m]",
    short_title: "Torque [N m]",
    series: &[
        Series {
            name: "load estimate",
            short: "load",
            color: Color::Red,
            get: |r| Some(r.t.load_torque as f64),
            drive: true,
        },
        Series {
            name: "torque estimate",
            short: "torque",
            color: Color::Cyan,
            get: |r| Some(r.t.torque as f64),
            drive: true,
        },
    ],
    nonneg: false,
};
const BUS: Spec = Spec {
    title: "DC bus [V]",
    short_title: "Bus [V]",
    series: &[Series {
        name: "dc bus",
        short: "bus",
        color: Color::Yellow,
        get: |r| Some(r.t.dc_bus as f64),
        drive: false,
    }],
    nonneg: true,
};
/// The board's control interrupt: mean and max over each sample's window, 170 MHz core
/// cycles.
const ISR: Spec = Spec {
    title: "Interrupt time [cycles]",
    short_title: "Interrupt [cycles]",
    series: &[
        Series {
            name: "mean",
            short: "mean",
            color: Color::Cyan,
            get: |r| Some(r.t.cycles_mean as f64),
            drive: false,
        },
        Series {
            name: "max",
            short: "max",
            color: Color::Red,
            get: |r| Some(r.t.cycles_max as f64),
            drive: false,
        },
    ],
    nonneg: true,
};
/// The virtual board's control step timed on the host (it sends it as 170 MHz cycles):
/// mean and max over each sample's window, microseconds.
const HOST_STEP: Spec = Spec {
    title: "Host step time [us] (virtual board)",
    short_title: "Host step [us]",
    series: &[
        Series {
            name: "mean",
            short: "mean",
            color: Color::Cyan,
            get: |r| Some(cycles_to_us(r.t.cycles_mean)),
            drive: false,
        },
        Series {
            name: "max",
            short: "max",
            color: Color::Red,
            get: |r| Some(cycles_to_us(r.t.cycles_max)),
            drive: false,
        },
    ],
    nonneg: true,
};

/// 170 MHz core cycles as microseconds.
fn cycles_to_us(cycles: u32) -> f64 {
    cycles as f64 / (SYSCLK_HZ as f64 * 1e-6)
}

/// The interrupt-time chart for the board connected.
fn isr_spec(app: &App) -> &'static Spec {
    if app.is_virtual_board() {
        &HOST_STEP
    } else {
        &ISR
    }
}

/// How held values are drawn: grey and dim.
fn held_style() -> Style {
    Style::default()
        .fg(Color::DarkGray)
        .add_modifier(Modifier::DIM)
}

/// How the reason values are held is drawn.
fn held_tag(h: Held) -> Span<'static> {
    Span::styled(
        format!(" {} ", h.reason()),
        Style::default().fg(Color::Yellow),
    )
}

/// Whether the values of a series are held, and why.
fn series_held(app: &App, drive: bool) -> Option<Held> {
    app.held().filter(|h| h.everything() || drive)
}

fn fmt_num(v: f64) -> String {
    let a = v.abs();
    if a >= 1000.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 0.1 || a == 0.0 {
        format!("{v:.2}")
    } else {
        format!("{v:.4}")
    }
}

/// A value in at most about six characters: two decimals below 10.
fn fmt_short(v: f64) -> String {
    let a = v.abs();
    if a >= 1000.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// A chart's vertical bounds, in the data's unit: the data's range padded by 8 % (at
/// least 2 % of the largest magnitude, at least 0.001), 0..1 without data. `nonneg`: the
/// quantity cannot be negative, so the lower bound is at least 0 (and 0..1 if all the
/// data is 0).
pub fn y_bounds(values: impl IntoIterator<Item = f64>, nonneg: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    if nonneg && hi <= 0.0 {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08)
        .max(hi.abs().max(lo.abs()) * 0.02)
        .max(1e-3);
    let lo = if nonneg {
        (lo - pad).max(0.0)
    } else {
        lo - pad
    };
    (lo, hi + pad)
}

fn chart(f: &mut Frame, area: Rect, app: &App, spec: &Spec, compact: bool) {
    let (t0, t1) = match (app.rows.front(), app.rows.back()) {
        (Some(a), Some(b)) => (
            (b.time_s - app.window_s).max(a.time_s.min(b.time_s)),
            b.time_s,
        ),
        _ => (0.0, app.window_s),
    };
    let t1 = if t1 > t0 { t1 } else { t0 + 1.0 };
    let data: Vec<Vec<(f64, f64)>> = spec
        .series
        .iter()
        .map(|s| {
            app.rows
                .iter()
                .filter_map(|r| (s.get)(r).map(|v| (r.time_s, v)))
                .collect()
        })
        .collect();
    let (lo, hi) = y_bounds(data.iter().flatten().map(|p| p.1), spec.nonneg);
    let datasets: Vec<Dataset> = spec
        .series
        .iter()
        .zip(&data)
        .filter(|(_, d)| !d.is_empty())
        .map(|(s, d)| {
            Dataset::default()
                .name(s.name)
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::default().fg(s.color))
                .data(d)
        })
        .collect();
    // the legend: each name in its colour with its latest value, dim if held
    let mut held = None;
    let legend: Vec<Span> = spec
        .series
        .iter()
        .zip(&data)
        .filter_map(|(s, d)| {
            let p = d.last()?;
            let h = series_held(app, s.drive);
            held = held.or(h);
            let style = if h.is_some() {
                held_style()
            } else {
                Style::default().fg(s.color)
            };
            let text = if compact {
                // 38 columns for up to four values
                format!(" {} {}", s.short, fmt_short(p.1))
            } else {
                format!(" {} {} ", s.name, fmt_num(p.1))
            };
            Some(Span::styled(text, style))
        })
        .collect();
    let mut legend = legend;
    if compact && !legend.is_empty() {
        legend.push(Span::raw(" "));
    }
    let mut title = vec![Span::styled(
        format!(
            " {} ",
            if compact {
                spec.short_title
            } else {
                spec.title
            }
        ),
        Style::default().add_modifier(Modifier::BOLD),
    )];
    let mut block = Block::default().borders(Borders::ALL);
    let mut x_axis = Axis::default().bounds([t0, t1]);
    if compact {
        // the short title and why values are held on top, the legend below
        title.extend(held.map(held_tag));
        block = block
            .title(Line::from(title))
            .title_bottom(Line::from(legend));
    } else {
        // the legend on top, why values are held below (a long legend fills the top)
        title.extend(legend);
        block = block.title(Line::from(title));
        if let Some(h) = held {
            block = block.title_bottom(Line::from(held_tag(h)).alignment(Alignment::Right));
        }
        x_axis = x_axis.title("t [s]").labels(vec![
            format!("{t0:.1}"),
            format!("{:.1}", (t0 + t1) / 2.0),
            format!("{t1:.1}"),
        ]);
    }
    let c = Chart::new(datasets)
        .block(block)
        .x_axis(x_axis)
        .y_axis(Axis::default().bounds([lo, hi]).labels(vec![
            fmt_num(lo),
            fmt_num((lo + hi) / 2.0),
            fmt_num(hi),
        ]))
        // the title (or the lower border) is the legend: a legend box would hide the
        // newest data in a small chart
        .legend_position(None);
    f.render_widget(c, area);
}

/// The status lines: the drive state and fault first (a narrow terminal cuts the
/// rest), then the link, the board time (s) and the board; then the recording, the
/// plots' time span (s of board time), the reconnections, the frames received, dropped
/// (bad) and the samples missing from the sequence (missed).
/// `named`: the monitor's name at the end (where the terminal is wide enough).
fn status(app: &App, named: bool) -> Vec<Line<'static>> {
    let (link, color) = match &app.link {
        LinkState::Connecting => (format!("connecting to {}", app.source), Color::Yellow),
        LinkState::Connected => (format!("connected to {}", app.source), Color::Green),
        LinkState::Retrying(r) => (format!("LINK LOST ({r}), retrying"), Color::Red),
    };
    let (state, fault) = app.state_text();
    // the last state received, not the board's now
    let stale = matches!(app.held(), Some(Held::LinkDown | Held::NoTelemetry));
    let state_style = if stale {
        held_style()
    } else {
        Style::default().add_modifier(Modifier::BOLD)
    };
    let fault_style = if stale {
        held_style()
    } else if fault == "none" || fault == "-" {
        Style::default()
    } else {
        Style::default().fg(Color::Red).add_modifier(Modifier::BOLD)
    };
    let t = app
        .latest()
        .map_or("-".into(), |r| format!("{:.2} s", r.time_s));
    let proto = app
        .version
        .map_or("protocol 0 (no hello)".into(), |v| format!("protocol {v}"));
    let mut first = vec![
        Span::raw(" state "),
        Span::styled(state, state_style),
        Span::raw(" | fault "),
        Span::styled(fault, fault_style),
        Span::raw(" | "),
        Span::styled(link, Style::default().fg(color)),
        Span::raw(format!(" | board time {t} | {proto}")),
    ];
    if !app.board.is_empty() {
        first.push(Span::raw(format!(" | {}", app.board)));
    }
    let rec = match &app.recorder {
        Some(r) => format!("REC {} ({} rows)", r.path().display(), r.rows()),
        None => "not recording".into(),
    };
    let mut second = Vec::new();
    if app.paused {
        second.push(Span::styled(
            " PAUSED",
            Style::default()
                .fg(Color::Yellow)
                .add_modifier(Modifier::BOLD),
        ));
        second.push(Span::raw(" |"));
    }
    // missed: samples missing from the sequence (lost frames, time disconnected)
    second.push(Span::raw(format!(
        " {rec} | window {} s | reconnects {} | frames {}, bad {}, missed {} ",
        app.window_s, app.reconnects, app.frames, app.bad_frames, app.missed
    )));
    if named {
        second.push(Span::styled(
            " acim-monitor ",
            Style::default().add_modifier(Modifier::REVERSED),
        ));
    }
    vec![Line::from(first), Line::from(second)]
}

/// The drive's readout: every telemetry value as a number (`compact`: those the compact
/// layout has no chart for), then the parameters.
fn readout(f: &mut Frame, area: Rect, app: &App, compact: bool) {
    let drive = |text: String| match series_held(app, true) {
        Some(_) => Span::styled(text, held_style()),
        None => Span::raw(text),
    };
    let board = |text: String| match series_held(app, false) {
        Some(_) => Span::styled(text, held_style()),
        None => Span::raw(text),
    };
    let mut lines: Vec<Line> = Vec::new();
    if let Some(r) = app.last() {
        let t = &r.t;
        let isr = match (app.is_virtual_board(), compact) {
            (true, false) => format!(
                "host step {:.2} / {:.2} / {:.2} us (min/mean/max)",
                cycles_to_us(t.cycles_min),
                cycles_to_us(t.cycles_mean),
                cycles_to_us(t.cycles_max)
            ),
            (true, true) => format!(
                "host step mean {:.2}  max {:.2} us",
                cycles_to_us(t.cycles_mean),
                cycles_to_us(t.cycles_max)
            ),
            (false, false) => format!(
                "interrupt {} / {} / {} cycles (min/mean/max)",
                t.cycles_min, t.cycles_mean, t.cycles_max
            ),
            (false, true) => format!(
                "interrupt mean {}  max {} cycles",
                t.cycles_mean, t.cycles_max
            ),
        };
        if compact {
            // 38 columns at 80 x 24
            lines.push(Line::from(vec![
                board(format!("bus {:.1} V", t.dc_bus)),
                drive(format!("   flux {:.3} Wb", t.flux)),
            ]));
            lines.push(Line::from(drive(format!("Rs {:.3} ohm", t.rs))));
            lines.push(Line::from(board(isr)));
        } else {
            lines.push(Line::from(vec![
                drive(format!(
                    "speed ref {:.1}  est {:.1}",
                    t.speed_ref_rpm, t.speed_est_rpm
                )),
                board(format!("  true {:.1} rpm", t.plant_speed_rpm)),
            ]));
            lines.push(Line::from(drive(format!(
                "i_d {:.3}  i_q {:.3} A   refs {}",
                t.i_d,
                t.i_q,
                r.x.map_or("-".into(), |x| format!(
                    "{:.3} / {:.3} A",
                    x.i_d_ref, x.i_q_ref
                ))
            ))));
            lines.push(Line::from(vec![
                drive(format!(
                    "flux {:.3} Wb  Rs {:.3} ohm  load {:.3} N m",
                    t.flux, t.rs, t.load_torque
                )),
                board(format!("  bus {:.1} V", t.dc_bus)),
            ]));
            lines.push(Line::from(board(isr)));
        }
    }
    lines.push(Line::from(Span::styled(
        "parameters (get / set <name> <value>):",
        Style::default().add_modifier(Modifier::BOLD),
    )));
    if app.params.is_empty() {
        lines.push(Line::from("  (none read yet: type get)"));
    }
    let cols = if compact { 1 } else { 2 };
    for pair in app.params.chunks(cols) {
        let s: Vec<String> = pair.iter().map(|(n, v)| format!("{n} {v}")).collect();
        lines.push(Line::from(format!("  {}", s.join("   "))));
    }
    let mut title = vec![Span::styled(
        " Drive ",
        Style::default().add_modifier(Modifier::BOLD),
    )];
    title.extend(app.held().map(held_tag));
    f.render_widget(
        Paragraph::new(lines).block(
            Block::default()
                .borders(Borders::ALL)
                .title(Line::from(title)),
        ),
        area,
    );
}

/// `text` broken into lines of at most `width` characters: at spaces where it can (a
/// space at a break is dropped), a word longer than a line is split; continuation lines
/// are indented by two spaces. Never empty.
pub fn wrap(text: &str, width: u16) -> Vec<String> {
    const INDENT: usize = 2;
    let width = (width as usize).max(INDENT + 1);
    let mut out: Vec<String> = Vec::new();
    let mut line = String::new();
    let mut len = 0; // characters in `line`
    let mut fresh = true; // nothing on `line` yet but its indent
    let mut next_line = |line: &mut String, len: &mut usize| {
        out.push(std::mem::replace(line, " ".repeat(INDENT)));
        *len = INDENT;
    };
    for word in text.split(' ') {
        let w: Vec<char> = word.chars().collect();
        let sep = usize::from(!fresh);
        if len + sep + w.len() <= width {
            if !fresh {
                line.push(' ');
            }
            line.extend(&w);
            len += sep + w.len();
            fresh = false;
        } else if w.is_empty() {
            // a space at the break
        } else if w.len() <= width - INDENT {
            next_line(&mut line, &mut len);
            line.extend(&w);
            len += w.len();
        } else {
            // longer than a line: split
            if !fresh && len + 1 < width {
                line.push(' ');
                len += 1;
            } else if !fresh {
                next_line(&mut line, &mut len);
            }
            let mut rest = &w[..];
            loop {
                let take = (width - len).min(rest.len());
                line.extend(&rest[..take]);
                len += take;
                rest = &rest[take..];
                if rest.is_empty() {
                    break;
                }
                next_line(&mut line, &mut len);
            }
            fresh = false;
        }
    }
    out.push(line);
    out
}

fn replies(f: &mut Frame, area: Rect, app: &App, compact: bool) {
    let (title, borders) = if compact {
        (" Replies (red: refused) PgUp/PgDn Home/End ", Borders::TOP)
    } else {
        (
            " Board replies (errors in red: the command changed nothing; PgUp/PgDn scroll, Home/End oldest/newest) ",
            Borders::ALL,
        )
    };
    let inner = Block::default().borders(borders).inner(area);
    app.reply_view.set((inner.width, inner.height));
    let mut lines: Vec<Line> = Vec::new();
    for m in &app.messages {
        let style = if m.error {
            Style::default().fg(Color::Red)
        } else if m.sent {
            Style::default().fg(Color::DarkGray)
        } else {
            Style::default()
        };
        lines.extend(
            wrap(&m.text, inner.width)
                .into_iter()
                .map(|l| Line::from(Span::styled(l, style))),
        );
    }
    let rows = inner.height as usize;
    let scroll = app.reply_scroll.min(lines.len().saturating_sub(rows));
    let end = lines.len() - scroll;
    let start = end.saturating_sub(rows);
    let mut block = Block::default().borders(borders).title(title);
    let lines_ = |n: usize| if n == 1 { "line" } else { "lines" };
    let more = match (start, scroll) {
        (_, 1..) => Some(format!(
            " {scroll} newer {} below: PgDn, End ",
            lines_(scroll)
        )),
        (1.., 0) => Some(format!(" {start} older {} above: PgUp ", lines_(start))),
        _ => None,
    };
    if let Some(m) = more {
        block = block.title(
            Line::from(Span::styled(m, Style::default().fg(Color::Yellow)))
                .alignment(Alignment::Right),
        );
    }
    let shown: Vec<Line> = lines.drain(start..end).collect();
    f.render_widget(Paragraph::new(shown).block(block), area);
}

fn command_line(f: &mut Frame, area: Rect, app: &App, compact: bool) {
    let borders = if compact { Borders::TOP } else { Borders::ALL };
    let block = Block::default()
        .borders(borders)
        .title(" Command (Enter sends; F1 or :help; Esc sends stop; Ctrl-C quits) ");
    let inner = block.inner(area);
    // the end of a line longer than the box
    let room = (inner.width as usize).saturating_sub(3);
    let n = app.input.chars().count();
    let shown: String = app.input.chars().skip(n.saturating_sub(room)).collect();
    let x = inner.x + 2 + shown.chars().count() as u16;
    f.render_widget(Paragraph::new(format!("> {shown}")).block(block), area);
    if inner.height > 0 {
        f.set_cursor_position((x.min(inner.right().saturating_sub(1)), inner.y));
    }
}

/// The layout for a terminal of this size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Below [`MIN_WIDTH`] x [`MIN_HEIGHT`]: a banner.
    TooSmall,
    /// Speed, currents, torque and the readout.
    Compact,
    /// All seven charts.
    Full,
}

/// The layout drawn in `area`.
pub fn mode(area: Rect) -> Mode {
    if area.width < MIN_WIDTH || area.height < MIN_HEIGHT {
        Mode::TooSmall
    } else if area.width >= FULL_WIDTH && area.height >= FULL_HEIGHT {
        Mode::Full
    } else {
        Mode::Compact
    }
}

fn grid(area: Rect, rows: u32, cols: u32) -> Vec<Rect> {
    Layout::default()
        .direction(Direction::Vertical)
        .constraints((0..rows).map(|_| Constraint::Ratio(1, rows)))
        .split(area)
        .iter()
        .flat_map(|r| {
            Layout::default()
                .direction(Direction::Horizontal)
                .constraints((0..cols).map(|_| Constraint::Ratio(1, cols)))
                .split(*r)
                .to_vec()
        })
        .collect()
}

fn too_small(f: &mut Frame, app: &App) {
    let area = f.area();
    let parts = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Max(3),
            Constraint::Min(0),
            Constraint::Length(1),
        ])
        .split(area);
    let first = status(app, false).swap_remove(0);
    f.render_widget(Paragraph::new(first).wrap(Wrap { trim: true }), parts[0]);
    let said = [
        format!(
            "This terminal is {}x{}: the monitor needs at least {MIN_WIDTH}x{MIN_HEIGHT}.",
            area.width, area.height
        ),
        "Please enlarge the window (or make the font smaller).".into(),
        "The keys still work: Enter sends the command line, Esc sends stop, Ctrl-C quits.".into(),
    ];
    // the rows it takes (at most: ratatui wraps these without an indent)
    let height = 2 + said
        .iter()
        .map(|l| wrap(l, parts[1].width.saturating_sub(2)).len() as u16)
        .sum::<u16>();
    let mut text: Vec<Line> = said.into_iter().map(Line::from).collect();
    text[0] = text[0]
        .clone()
        .style(Style::default().add_modifier(Modifier::BOLD));
    let banner = Paragraph::new(text)
        .alignment(Alignment::Center)
        .wrap(Wrap { trim: true })
        .block(
            Block::default()
                .borders(Borders::ALL)
                .border_style(Style::default().fg(Color::Yellow))
                .title(" acim-monitor: terminal too small "),
        );
    // its own height, in the middle of the rows left
    let middle = Layout::default()
        .direction(Direction::Vertical)
        .constraints([Constraint::Length(height)])
        .flex(Flex::Center)
        .split(parts[1]);
    f.render_widget(banner, middle[0]);
    let p = parts[2];
    if p.height > 0 {
        let room = (p.width as usize).saturating_sub(3);
        let n = app.input.chars().count();
        let shown: String = app.input.chars().skip(n.saturating_sub(room)).collect();
        let x = p.x + 2 + shown.chars().count() as u16;
        f.render_widget(Paragraph::new(format!("> {shown}")), p);
        f.set_cursor_position((x.min(p.right().saturating_sub(1)), p.y));
    }
}

/// Draws the whole screen.
pub fn render(f: &mut Frame, app: &App) {
    let area = f.area();
    let m = mode(area);
    if m == Mode::TooSmall {
        too_small(f, app);
        return;
    }
    let compact = m == Mode::Compact;
    // the compact layout's replies and command line have only their top border
    let (reply_rows, command_rows) = if compact {
        ((area.height / 3).clamp(8, 14), 2)
    } else {
        ((area.height / 6).clamp(8, 12), 3)
    };
    let outer = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Length(2),
            Constraint::Min(10),
            Constraint::Length(reply_rows),
            Constraint::Length(command_rows),
        ])
        .split(area);
    f.render_widget(Paragraph::new(status(app, !compact)), outer[0]);
    if compact {
        let c = grid(outer[1], 2, 2);
        chart(f, c[0], app, &SPEED, true);
        chart(f, c[1], app, &CURRENTS, true);
        chart(f, c[2], app, &TORQUE, true);
        readout(f, c[3], app, true);
    } else {
        let c = grid(outer[1], 4, 2);
        chart(f, c[0], app, &SPEED, false);
        chart(f, c[1], app, &CURRENTS, false);
        chart(f, c[2], app, &FLUX, false);
        chart(f, c[3], app, &RS, false);
        chart(f, c[4], app, &TORQUE, false);
        chart(f, c[5], app, &BUS, false);
        chart(f, c[6], app, isr_spec(app), false);
        readout(f, c[7], app, false);
    }
    replies(f, outer[2], app, compact);
    command_line(f, outer[3], app, compact);
}

/// The screen of `app` at `width` x `height` characters, as text (one line per row,
/// trailing spaces removed).
pub fn screenshot(app: &App, width: u16, height: u16) -> String {
    let buf = screen(app, width, height);
    let mut out = String::new();
    for y in 0..buf.area.height {
        let mut line = String::new();
        for x in 0..buf.area.width {
            line.push_str(buf[(x, y)].symbol());
        }
        out.push_str(line.trim_end());
        out.push('\n');
    }
    out
}

/// The screen of `app` at `width` x `height` characters, with its styles.
pub fn screen(app: &App, width: u16, height: u16) -> ratatui::buffer::Buffer {
    let Ok(mut term) = Terminal::new(TestBackend::new(width, height));
    if term.draw(|f| render(f, app)).is_err() {
        return ratatui::buffer::Buffer::empty(Rect::new(0, 0, width, height));
    }
    term.backend().buffer().clone()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::Event;
    use acim_firmware_core::protocol::Extension;
    use acim_firmware_core::telemetry::TelemetrySample;
    use std::time::Duration;

    /// The commissioning's last reply line, pending its apply (about 110 characters).
    const IDENTIFIED: &str = "ok commissioned: send 'commission apply' to use these settings (or 'commission <P W> <V> <A> <Hz> <rpm>' to repeat)";

    /// A monitor connected to `board`, fed `n` samples 0.01 s of board time apart in
    /// drive state `state` with fault `fault`.
    fn fed(board: &str, state: u8, fault: u8, n: u32) -> App {
        let mut app = App::new("tcp 127.0.0.1:7878".into());
        app.on_event(Event::Connected);
        app.on_event(Event::Hello {
            version: 1,
            pwm_hz: 5000,
            board: board.into(),
        });
        for k in 1..=n {
            let x = k as f32 / n as f32;
            app.on_event(Event::Telemetry(TelemetrySample {
                seq: k,
                state,
                fault,
                speed_ref_rpm: 500.0,
                speed_est_rpm: 500.0 * x,
                plant_speed_rpm: 499.0 * x,
                i_d: 1.5,
                i_q: 0.7 * x,
                torque: 1.6 * x,
                load_torque: 1.5 * x,
                rs: 10.5,
                flux: 0.78 * x,
                dc_bus: 325.0,
                ..Default::default()
            }));
            app.on_event(Event::Extension(Extension {
                seq: k,
                period: k * 50,
                i_d_ref: 1.5,
                i_q_ref: 0.7,
            }));
        }
        app
    }

    fn vboard(state: u8, fault: u8) -> App {
        fed(acim_vboard::board::BOARD_NAME, state, fault, 300)
    }

    /// Where `needle` starts on the screen (column, row): every cell here is one
    /// character wide.
    fn find(buf: &ratatui::buffer::Buffer, needle: &str) -> Option<(u16, u16)> {
        (0..buf.area.height).find_map(|y| {
            let row: Vec<&str> = (0..buf.area.width).map(|x| buf[(x, y)].symbol()).collect();
            let row = row.concat();
            let at = row.find(needle)?;
            Some((row[..at].chars().count() as u16, y))
        })
    }

    fn dim_at(buf: &ratatui::buffer::Buffer, needle: &str) -> bool {
        let (x, y) = find(buf, needle).unwrap_or_else(|| panic!("{needle:?} not on screen"));
        buf[(x, y)].modifier.contains(Modifier::DIM)
    }

    fn assert_fits(screen: &str, w: usize, h: usize) {
        assert_eq!(screen.lines().count(), h, "{screen}");
        assert!(screen.lines().all(|l| l.chars().count() <= w), "{screen}");
    }

    #[test]
    fn at_80x24_the_state_and_the_fault_come_first() {
        // the longest fault name, and a long link-loss reason after it
        let mut app = vboard(4, 16);
        let s = screenshot(&app, 80, 24);
        assert_fits(&s, 80, 24);
        let first = s.lines().next().unwrap();
        assert!(
            first.starts_with(" state Fault | fault HardwareBreak (break input) | "),
            "{s}"
        );
        app.on_event(Event::Disconnected {
            reason: "tcp 127.0.0.1:7878: Connection refused (os error 111)".into(),
            retry_in: Duration::from_millis(400),
        });
        let s = screenshot(&app, 80, 24);
        assert!(
            s.lines()
                .next()
                .unwrap()
                .starts_with(" state Fault | fault HardwareBreak (break input) | LINK LOST"),
            "{s}"
        );
        // the compact layout: three charts of several rows each, the readout, the replies
        assert_eq!(mode(Rect::new(0, 0, 80, 24)), Mode::Compact);
        for t in [
            "Speed [rpm]",
            "Currents [A]",
            "Torque [N m]",
            "Drive",
            "Replies",
            "Command",
        ] {
            assert!(s.contains(t), "{t:?}:\n{s}");
        }
        let plotted = s
            .lines()
            .filter(|l| l.chars().any(|c| ('\u{2801}'..='\u{28ff}').contains(&c)))
            .count();
        assert!(plotted >= 6, "{plotted} rows with plots:\n{s}");

        // before any sample, and a command line longer than the box (its end shows)
        let mut app = App::new("serial /dev/ttyACM0 @ 115200".into());
        app.input = format!("{}END", "x".repeat(117));
        let s = screenshot(&app, 80, 24);
        assert_fits(&s, 80, 24);
        assert!(
            s.starts_with(" state - | fault - | connecting to serial"),
            "{s}"
        );
        assert!(s.contains("xxxEND"), "{s}");
    }

    #[test]
    fn long_replies_are_wrapped_and_scroll() {
        let mut app = vboard(0, 0);
        app.on_event(Event::Sent("commission".into()));
        app.on_event(Event::Reply {
            text: IDENTIFIED.into(),
            error: false,
        });
        let s = screenshot(&app, 80, 24);
        assert_fits(&s, 80, 24);
        // its tail, on a continuation line
        assert!(s.contains("<Hz> <rpm>' to repeat)"), "{s}");
        assert!(
            s.contains("ok commissioned: send 'commission apply'"),
            "{s}"
        );

        for k in 0..30 {
            app.on_event(Event::Reply {
                text: format!("reply {k}"),
                error: false,
            });
        }
        let s = screenshot(&app, 80, 24);
        assert!(s.contains("reply 29") && !s.contains("reply 20\n"), "{s}");
        assert!(s.contains("older lines above: PgUp"), "{s}");
        // a page back, then a new reply: the view stays where it was
        app.scroll_replies(app.reply_page());
        let back = screenshot(&app, 80, 24);
        assert!(
            !back.contains("reply 29") && back.contains("reply 20"),
            "{back}"
        );
        assert!(back.contains("newer lines below: PgDn, End"), "{back}");
        app.on_event(Event::Reply {
            text: "reply 30".into(),
            error: false,
        });
        let still = screenshot(&app, 80, 24);
        let replies = |s: &str| -> Vec<String> {
            s.lines()
                .filter(|l| l.starts_with("reply "))
                .map(String::from)
                .collect()
        };
        assert_eq!(replies(&back), replies(&still));
        // the oldest: the commission reply, whole
        app.replies_oldest();
        let top = screenshot(&app, 80, 24);
        assert!(
            top.contains("ok commissioned: send") && top.contains("to repeat)"),
            "{top}"
        );
        app.replies_newest();
        assert!(screenshot(&app, 80, 24).contains("reply 30"));
        // in the full layout too
        app.scroll_replies(-1000);
        let big = screenshot(&app, 200, 50);
        assert!(big.contains("reply 30"), "{big}");
    }

    #[test]
    fn wrapping_keeps_every_character() {
        for w in [3u16, 8, 20, 78] {
            for text in [IDENTIFIED, "", "  two  spaces ", &"x".repeat(200)] {
                let lines = wrap(text, w);
                assert!(
                    lines.iter().all(|l| l.chars().count() <= w as usize),
                    "{w} {lines:?}"
                );
                let joined: String = lines.concat().chars().filter(|c| *c != ' ').collect();
                let want: String = text.chars().filter(|c| *c != ' ').collect();
                assert_eq!(joined, want, "{w} {lines:?}");
            }
        }
        assert_eq!(wrap("ok", 78), ["ok"]);
        assert_eq!(wrap("aaa bbb ccc", 7), ["aaa bbb", "  ccc"]);
        assert_eq!(wrap("abcdefghij", 6), ["abcdef", "  ghij"]);
    }

    #[test]
    fn below_80x24_a_banner_asks_for_a_larger_terminal() {
        let app = vboard(2, 0);
        for (w, h) in [(79, 24), (80, 23), (60, 20), (40, 12)] {
            assert_eq!(mode(Rect::new(0, 0, w, h)), Mode::TooSmall);
            let s = screenshot(&app, w, h);
            assert_fits(&s, w as usize, h as usize);
            assert!(s.contains("needs at least 80x24"), "{w}x{h}:\n{s}");
            assert!(
                s.contains(&format!("This terminal is {w}x{h}")),
                "{w}x{h}:\n{s}"
            );
            assert!(
                s.contains("state Running") && s.contains("fault none"),
                "{w}x{h}:\n{s}"
            );
            assert!(!s.contains("Speed [rpm]"), "{w}x{h}:\n{s}");
        }
        // tiny: no panic
        for (w, h) in [(1, 1), (10, 3), (80, 2)] {
            screenshot(&app, w, h);
        }
        assert_eq!(mode(Rect::new(0, 0, 80, 24)), Mode::Compact);
        assert_eq!(mode(Rect::new(0, 0, 200, 50)), Mode::Full);
    }

    #[test]
    fn held_values_are_dim_and_say_why() {
        // running: nothing held
        let app = vboard(2, 0);
        for (w, h) in [(80, 24), (200, 50)] {
            let b = screen(&app, w, h);
            assert!(find(&b, "held:").is_none(), "{}", screenshot(&app, w, h));
            assert!(!dim_at(&b, "est 500.0"));
        }
        // commissioning: the drive's values are held, the board's (bus, true speed) are live
        let app = vboard(5, 0);
        assert_eq!(app.held(), Some(Held::Commissioning));
        let b = screen(&app, 80, 24);
        let s = screenshot(&app, 80, 24);
        assert!(s.contains("Speed [rpm]  held: commissioning"), "{s}");
        assert!(s.contains("Drive  held: commissioning"), "{s}");
        assert!(dim_at(&b, "est 500.0"), "{s}");
        assert!(dim_at(&b, "flux 0.780 Wb"), "{s}");
        assert!(!dim_at(&b, "true 499.0"), "{s}");
        assert!(!dim_at(&b, "bus 325.0 V"), "{s}");
        let b = screen(&app, 200, 50);
        assert!(dim_at(&b, "estimate 500.0"));
        assert!(!dim_at(&b, "dc bus 325.0"));
        let s = screenshot(&app, 200, 50);
        let flux = s
            .lines()
            .position(|l| l.contains("Rotor flux [Wb]"))
            .unwrap();
        let below = s.lines().skip(flux).find(|l| l.starts_with('└')).unwrap();
        assert!(below.contains("held: commissioning"), "{s}");

        // the link down: everything held, the state and fault too
        let mut app = vboard(2, 0);
        app.on_event(Event::Disconnected {
            reason: "connection closed by the board".into(),
            retry_in: Duration::from_millis(100),
        });
        assert_eq!(app.held(), Some(Held::LinkDown));
        let b = screen(&app, 80, 24);
        let s = screenshot(&app, 80, 24);
        assert!(s.contains("held: link down"), "{s}");
        assert!(dim_at(&b, "true 499.0") && dim_at(&b, "bus 325.0 V"), "{s}");
        assert!(dim_at(&b, "Running"), "{s}");

        // connected but no telemetry for a while
        let mut app = vboard(2, 0);
        let t0 = std::time::Instant::now();
        app.tick(t0);
        app.tick(t0 + Duration::from_secs(1));
        assert_eq!(app.held(), None);
        app.tick(t0 + Duration::from_secs(3));
        assert_eq!(app.held(), Some(Held::NoTelemetry));
        assert!(screenshot(&app, 80, 24).contains("held: no telemetry"));
    }

    #[test]
    fn the_virtual_boards_host_step_time_has_no_negative_axis() {
        // untimed: every interrupt-time field 0
        let app = vboard(2, 0);
        let s = screenshot(&app, 200, 50);
        assert!(!s.contains("Interrupt time"), "{s}");
        let lines: Vec<&str> = s.lines().collect();
        let top = lines
            .iter()
            .position(|l| l.contains("Host step time [us] (virtual board)"))
            .unwrap_or_else(|| panic!("{s}"));
        let mut labels = 0;
        for l in &lines[top + 1..] {
            let chart: String = l.chars().take(100).collect();
            if chart.starts_with('└') {
                break;
            }
            // the y axis's label: between the border and the axis line
            let label = chart.split('│').nth(1).unwrap_or("").trim();
            if !label.is_empty() {
                labels += 1;
                assert!(!label.starts_with('-'), "{label:?}:\n{s}");
            }
        }
        assert!(labels >= 2, "{s}");
        assert!(
            s.contains("host step 0.00 / 0.00 / 0.00 us (min/mean/max)"),
            "{s}"
        );
        // a board: MCU cycles
        let fw = fed("acim-firmware power stage", 2, 0, 50);
        let s = screenshot(&fw, 200, 50);
        assert!(
            s.contains("Interrupt time [cycles]") && !s.contains("Host step"),
            "{s}"
        );
    }

    #[test]
    fn quantities_that_cannot_be_negative_start_at_zero() {
        assert_eq!(y_bounds([0.0; 5], true), (0.0, 1.0));
        assert_eq!(y_bounds([], true), (0.0, 1.0));
        let (lo, hi) = y_bounds([0.0, 0.01, 0.02], true);
        assert_eq!(lo, 0.0);
        assert!(hi > 0.02);
        let (lo, hi) = y_bounds([320.0, 330.0], true);
        assert!(lo > 300.0 && lo < 320.0 && hi > 330.0);
        // a speed can be negative
        let (lo, _) = y_bounds([0.0, 500.0], false);
        assert!(lo < 0.0);
        assert!(acim_vboard::board::BOARD_NAME.starts_with(crate::app::VIRTUAL_BOARD_PREFIX));
    }
}
