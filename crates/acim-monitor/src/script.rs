//! The headless mode's schedule: one `<time s> <command>` a line (`#` comments), each
//! sent when the board's telemetry has advanced that far since the first sample the
//! monitor received, e.g.
//!
//! ```text
//! 0.2 start
//! 0.5 speed 500
//! 2.5 load 1.5
//! 4.0 stop
//! ```

/// One scheduled command.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// Board time since the first sample, s.
    pub at_s: f64,
    /// The command line (a `:` line acts on the monitor).
    pub command: String,
}

/// Parses a schedule; errors name the line.
pub fn parse(text: &str) -> Result<Vec<Step>, String> {
    let mut steps: Vec<Step> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let (t, cmd) = line
            .split_once(char::is_whitespace)
            .ok_or_else(|| format!("script line {}: expected `<time s> <command>`", n + 1))?;
        let at_s: f64 = t
            .parse()
            .ok()
            .filter(|v: &f64| v.is_finite() && *v >= 0.0)
            .ok_or_else(|| format!("script line {}: bad time {t:?}", n + 1))?;
        if steps.last().is_some_and(|s| s.at_s > at_s) {
            return Err(format!("script line {}: times must not decrease", n + 1));
        }
        steps.push(Step {
            at_s,
            command: cmd.trim().to_string(),
        });
    }
    Ok(steps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn schedules_parse() {
        let s = parse("# x\n0.2 start\n\n0.5 speed 500 # fast\n").unwrap();
        assert_eq!(s.len(), 2);
        assert_eq!(s[1].command, "speed 500");
        assert!(parse("start").is_err());
        assert!(parse("x start").is_err());
        assert!(parse("1 a\n0.5 b").is_err());
    }
}
