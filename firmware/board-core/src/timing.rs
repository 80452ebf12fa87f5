//! Cycle-count statistics of the control step and the telemetry decimator (both run in
//! the control interrupt: integer-only, saturating, panic-free).

/// min/mean/max of the step's cycle counts over a window.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CycleStats {
    min: u32,
    max: u32,
    sum: u32,
    count: u32,
}

/// A finished window.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CycleSummary {
    /// Fewest cycles (0 if the window was empty).
    pub min: u32,
    /// Mean cycles, rounded down.
    pub mean: u32,
    /// Most cycles.
    pub max: u32,
    /// Steps in the window.
    pub count: u32,
}

impl Default for CycleStats {
    fn default() -> Self {
        Self::new()
    }
}

impl CycleStats {
    /// An empty window.
    pub const fn new() -> Self {
        Self {
            min: u32::MAX,
            max: 0,
            sum: 0,
            count: 0,
        }
    }

    /// Records one step's cycle count.
    #[inline]
    pub fn record(&mut self, cycles: u32) {
        self.min = self.min.min(cycles);
        self.max = self.max.max(cycles);
        self.sum = self.sum.saturating_add(cycles);
        self.count = self.count.saturating_add(1);
    }

    /// Closes the window: its summary, and a fresh window.
    #[inline]
    pub fn take(&mut self) -> CycleSummary {
        let s = CycleSummary {
            min: if self.count == 0 { 0 } else { self.min },
            // checked_div: no divide-by-zero panic path
            mean: self.sum.checked_div(self.count).unwrap_or(0),
            max: self.max,
            count: self.count,
        };
        *self = Self::new();
        s
    }
}

/// Fires once every `every` calls.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decimator {
    every: u16,
    count: u16,
}

impl Decimator {
    /// Fires on every `every`-th tick (`every` of 0 is taken as 1).
    pub const fn new(every: u16) -> Self {
        Self {
            every: if every == 0 { 1 } else { every },
            count: 0,
        }
    }

    /// The periods between two firings (at least 1).
    pub const fn every(&self) -> u16 {
        self.every
    }

    /// Counts one period; true on every `every`-th.
    #[inline]
    pub fn tick(&mut self) -> bool {
        self.count += 1;
        if self.count >= self.every {
            self.count = 0;
            true
        } else {
            false
        }
    }
}

/// Elapsed cycles between two reads of a free-running 32-bit counter (wrap-safe).
#[inline]
pub fn elapsed(start: u32, end: u32) -> u32 {
    end.wrapping_sub(start)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_window() {
        let mut s = CycleStats::new();
        assert_eq!(s.take(), CycleSummary::default());
        for c in [2000, 2500, 3000] {
            s.record(c);
        }
        assert_eq!(
            s.take(),
            CycleSummary {
                min: 2000,
                mean: 2500,
                max: 3000,
                count: 3
            }
        );
        s.record(7);
        assert_eq!(s.take().min, 7, "window restarted");
        // saturation instead of overflow
        s.record(u32::MAX);
        s.record(u32::MAX);
        let t = s.take();
        assert_eq!(t.max, u32::MAX);
        assert_eq!(t.mean, u32::MAX / 2);
    }

    #[test]
    fn decimator() {
        let mut d = Decimator::new(500);
        let fired = (0..5000).filter(|_| d.tick()).count();
        assert_eq!(fired, 10);
        let mut one = Decimator::new(0);
        assert!(one.tick() && one.tick());
    }

    #[test]
    fn elapsed_wraps() {
        assert_eq!(elapsed(u32::MAX - 9, 10), 20);
        assert_eq!(elapsed(100, 2100), 2000);
    }
}
