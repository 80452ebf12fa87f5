//! The screen: a status line, seven live charts and a readout, the board's replies and
//! the command line. [`render`] draws the [`App`]; [`screenshot`] renders it into
//! ratatui's test backend and returns the screen as text (what CI checks and the README
//! shows).

use crate::app::{App, LinkState, Row};
use ratatui::backend::TestBackend;
use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType, Paragraph};
use ratatui::{Frame, Terminal};

type Series = (&'static str, Color, fn(&Row) -> Option<f64>);

const SPEED: &[Series] = &[
    ("reference", Color::Yellow, |r| {
        Some(r.t.speed_ref_rpm as f64)
    }),
    ("estimate", Color::Cyan, |r| Some(r.t.speed_est_rpm as f64)),
    ("true (model)", Color::Green, |r| {
        Some(r.t.plant_speed_rpm as f64)
    }),
];
const CURRENTS: &[Series] = &[
    ("i_d", Color::Cyan, |r| Some(r.t.i_d as f64)),
    ("i_q", Color::Magenta, |r| Some(r.t.i_q as f64)),
    ("i_d ref", Color::Blue, |r| r.x.map(|x| x.i_d_ref as f64)),
    ("i_q ref", Color::Red, |r| r.x.map(|x| x.i_q_ref as f64)),
];
const FLUX: &[Series] = &[("model flux", Color::Cyan, |r| Some(r.t.flux as f64))];
const RS: &[Series] = &[("Rs estimate", Color::Yellow, |r| Some(r.t.rs as f64))];
const TORQUE: &[Series] = &[
    ("load estimate", Color::Red, |r| {
        Some(r.t.load_torque as f64)
    }),
    ("torque estimate", Color::Cyan, |r| Some(r.t.torque as f64)),
];
const BUS: &[Series] = &[("dc bus", Color::Yellow, |r| Some(r.t.dc_bus as f64))];
const ISR: &[Series] = &[
    ("mean", Color::Cyan, |r| Some(r.t.cycles_mean as f64)),
    ("max", Color::Red, |r| Some(r.t.cycles_max as f64)),
];

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

fn chart(f: &mut Frame, area: Rect, app: &App, title: &str, series: &[Series]) {
    let (t0, t1) = match (app.rows.front(), app.rows.back()) {
        (Some(a), Some(b)) => (
            (b.time_s - app.window_s).max(a.time_s.min(b.time_s)),
            b.time_s,
        ),
        _ => (0.0, app.window_s),
    };
    let t1 = if t1 > t0 { t1 } else { t0 + 1.0 };
    let data: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|(_, _, get)| {
            app.rows
                .iter()
                .filter_map(|r| get(r).map(|v| (r.time_s, v)))
                .collect()
        })
        .collect();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in data.iter().flatten() {
        lo = lo.min(p.1);
        hi = hi.max(p.1);
    }
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08)
        .max(hi.abs().max(lo.abs()) * 0.02)
        .max(1e-3);
    let (lo, hi) = (lo - pad, hi + pad);
    let datasets: Vec<Dataset> = series
        .iter()
        .zip(&data)
        .filter(|(_, d)| !d.is_empty())
        .map(|((name, color, _), d)| {
            Dataset::default()
                .name(*name)
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::default().fg(*color))
                .data(d)
        })
        .collect();
    let latest: Vec<Span> = series
        .iter()
        .zip(&data)
        .filter_map(|((name, color, _), d)| {
            d.last().map(|p| {
                Span::styled(
                    format!(" {name} {} ", fmt_num(p.1)),
                    Style::default().fg(*color),
                )
            })
        })
        .collect();
    let mut title_line = vec![Span::styled(
        format!(" {title} "),
        Style::default().add_modifier(Modifier::BOLD),
    )];
    title_line.extend(latest);
    let c = Chart::new(datasets)
        .block(
            Block::default()
                .borders(Borders::ALL)
                .title(Line::from(title_line)),
        )
        .x_axis(Axis::default().title("t [s]").bounds([t0, t1]).labels(vec![
            format!("{t0:.1}"),
            format!("{:.1}", (t0 + t1) / 2.0),
            format!("{t1:.1}"),
        ]))
        .y_axis(Axis::default().bounds([lo, hi]).labels(vec![
            fmt_num(lo),
            fmt_num((lo + hi) / 2.0),
            fmt_num(hi),
        ]))
        // the title is the legend (each name in its colour, with its latest value): a
        // legend box would hide the newest data in a small chart
        .legend_position(None);
    f.render_widget(c, area);
}

fn status(app: &App) -> Vec<Line<'static>> {
    let (link, color) = match &app.link {
        LinkState::Connecting => ("connecting".to_string(), Color::Yellow),
        LinkState::Connected => ("connected".to_string(), Color::Green),
        LinkState::Retrying(r) => (format!("LINK LOST ({r}), retrying"), Color::Red),
    };
    let (state, fault) = app.state_text();
    let fault_style = if fault == "none" || fault == "-" {
        Style::default()
    } else {
        Style::default().fg(Color::Red).add_modifier(Modifier::BOLD)
    };
    let t = app
        .last()
        .map_or("-".into(), |r| format!("{:.2} s", r.time_s));
    let rec = match &app.recorder {
        Some(r) => format!("REC {} ({} rows)", r.path().display(), r.rows()),
        None => "not recording".into(),
    };
    let proto = app
        .version
        .map_or("protocol 0 (no hello)".into(), |v| format!("protocol {v}"));
    vec![
        Line::from(vec![
            Span::styled(
                " acim-monitor ",
                Style::default().add_modifier(Modifier::REVERSED),
            ),
            Span::raw(format!(" {} ", app.source)),
            Span::styled(link, Style::default().fg(color)),
            Span::raw(format!(" | {proto} | board time {t} | state ")),
            Span::styled(state, Style::default().add_modifier(Modifier::BOLD)),
            Span::raw(" | fault "),
            Span::styled(fault, fault_style),
        ]),
        Line::from(format!(
            " {rec} | frames {} | bad frames {} | missed samples {} | reconnects {}{}",
            app.frames,
            app.bad_frames,
            app.missed,
            app.reconnects,
            if app.paused { " | PAUSED" } else { "" }
        )),
    ]
}

fn readout(f: &mut Frame, area: Rect, app: &App) {
    let mut lines: Vec<Line> = Vec::new();
    if let Some(r) = app.last() {
        let t = &r.t;
        lines.push(Line::from(format!(
            "speed ref {:.1}  est {:.1}  true {:.1} rpm",
            t.speed_ref_rpm, t.speed_est_rpm, t.plant_speed_rpm
        )));
        lines.push(Line::from(format!(
            "i_d {:.3}  i_q {:.3} A   refs {}",
            t.i_d,
            t.i_q,
            r.x.map_or("-".into(), |x| format!(
                "{:.3} / {:.3} A",
                x.i_d_ref, x.i_q_ref
            ))
        )));
        lines.push(Line::from(format!(
            "flux {:.3} Wb  Rs {:.3} ohm  load {:.3} N m  bus {:.1} V",
            t.flux, t.rs, t.load_torque, t.dc_bus
        )));
        lines.push(Line::from(format!(
            "interrupt {} / {} / {} cycles (min/mean/max)",
            t.cycles_min, t.cycles_mean, t.cycles_max
        )));
    }
    lines.push(Line::from(Span::styled(
        "parameters (get / set <name> <value>):",
        Style::default().add_modifier(Modifier::BOLD),
    )));
    if app.params.is_empty() {
        lines.push(Line::from("  (none read yet: type get)"));
    }
    let cols = 2usize;
    for pair in app.params.chunks(cols) {
        let s: Vec<String> = pair.iter().map(|(n, v)| format!("{n} {v}")).collect();
        lines.push(Line::from(format!("  {}", s.join("   "))));
    }
    // switched off, the drive stops updating its estimates: say so rather than let the
    // last running values pass for live ones
    let off = app.last().is_some_and(|r| r.t.state == 0 || r.t.state == 4);
    let title = if off {
        " Drive (off: estimates hold their last values) "
    } else {
        " Drive "
    };
    f.render_widget(
        Paragraph::new(lines).block(Block::default().borders(Borders::ALL).title(title)),
        area,
    );
}

/// Draws the whole screen.
pub fn render(f: &mut Frame, app: &App) {
    let outer = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Length(2),
            Constraint::Min(12),
            Constraint::Length(8),
            Constraint::Length(3),
        ])
        .split(f.area());
    f.render_widget(Paragraph::new(status(app)), outer[0]);
    let rows = Layout::default()
        .direction(Direction::Vertical)
        .constraints([Constraint::Ratio(1, 4); 4])
        .split(outer[1]);
    let cell = |i: usize| {
        Layout::default()
            .direction(Direction::Horizontal)
            .constraints([Constraint::Ratio(1, 2); 2])
            .split(rows[i])
    };
    let (r0, r1, r2, r3) = (cell(0), cell(1), cell(2), cell(3));
    chart(f, r0[0], app, "Speed [rpm]", SPEED);
    chart(f, r0[1], app, "Currents d/q [A]", CURRENTS);
    chart(f, r1[0], app, "Rotor flux [Wb]", FLUX);
    chart(f, r1[1], app, "Rs estimate [ohm]", RS);
    chart(f, r2[0], app, "Torque [N m]", TORQUE);
    chart(f, r2[1], app, "DC bus [V]", BUS);
    chart(f, r3[0], app, "Interrupt time [cycles]", ISR);
    readout(f, r3[1], app);
    let shown = outer[2].height.saturating_sub(2) as usize;
    let msgs: Vec<Line> = app
        .messages
        .iter()
        .skip(app.messages.len().saturating_sub(shown))
        .map(|m| {
            let style = if m.error {
                Style::default().fg(Color::Red)
            } else if m.sent {
                Style::default().fg(Color::DarkGray)
            } else {
                Style::default()
            };
            Line::from(Span::styled(m.text.clone(), style))
        })
        .collect();
    f.render_widget(
        Paragraph::new(msgs).block(
            Block::default()
                .borders(Borders::ALL)
                .title(" Board replies (errors in red: the command changed nothing) "),
        ),
        outer[2],
    );
    f.render_widget(
        Paragraph::new(format!("> {}", app.input)).block(
            Block::default()
                .borders(Borders::ALL)
                .title(" Command (Enter sends; :help; Esc sends stop; Ctrl-C quits) "),
        ),
        outer[3],
    );
    let x = outer[3].x + 3 + app.input.chars().count() as u16;
    f.set_cursor_position((x.min(outer[3].right().saturating_sub(2)), outer[3].y + 1));
}

/// The screen of `app` at `width` x `height` characters, as text (one line per row,
/// trailing spaces removed).
pub fn screenshot(app: &App, width: u16, height: u16) -> String {
    let Ok(mut term) = Terminal::new(TestBackend::new(width, height));
    if term.draw(|f| render(f, app)).is_err() {
        return String::new();
    }
    let buf = term.backend().buffer();
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
