//! DC link: a stiff source, or a diode rectifier charging the bus capacitor through a
//! source resistance (no braking chopper), integrated once per control period with the
//! inverter's mean DC current of that period. The source may carry a sinusoidal ripple
//! (a rectifier's 100 Hz on a small capacitor, as a fraction of the source voltage).

use acim::frames::{FastSinCos, SinCos};
use acim::math::wrap_angle;

/// DC-link model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DcLink {
    /// Source (rectified mains) voltage, V.
    source_v: f32,
    /// Bus capacitance, F (0: stiff bus, the bus follows the source).
    capacitance_f: f32,
    /// Source resistance, ohm.
    source_resistance_ohm: f32,
    /// Bus voltage, V.
    bus_v: f32,
    /// Ripple amplitude as a fraction of the source voltage (0: none).
    ripple_fraction: f32,
    /// Ripple frequency, rad/s.
    ripple_frequency: f32,
    /// Ripple phase, rad (wrapped: no loss of precision over long runs).
    ripple_phase: f32,
}

impl DcLink {
    /// A link charged to `source_v` (V) with `capacitance_f` (F; 0 or less: stiff) fed
    /// through `source_resistance_ohm` (ohm; 0 or less: stiff as well, the source then
    /// holds the bus).
    pub fn new(source_v: f32, capacitance_f: f32, source_resistance_ohm: f32) -> Self {
        Self {
            source_v,
            capacitance_f,
            source_resistance_ohm,
            bus_v: source_v,
            ripple_fraction: 0.0,
            ripple_frequency: 0.0,
            ripple_phase: 0.0,
        }
    }

    /// The same link with a sinusoidal ripple on its source: `fraction` of the source
    /// voltage (0.1 = +/-10 %) at `frequency_hz` (100 Hz: a single-phase rectifier on
    /// 50 Hz mains). The bus starts at the ripple's zero crossing.
    pub fn with_ripple(mut self, fraction: f32, frequency_hz: f32) -> Self {
        self.ripple_fraction = fraction;
        self.ripple_frequency = 2.0 * core::f32::consts::PI * frequency_hz;
        self
    }

    /// The source voltage this instant, ripple included, V.
    fn source_now(&self) -> f32 {
        if self.ripple_fraction == 0.0 {
            return self.source_v;
        }
        let s = FastSinCos.sin_cos(self.ripple_phase).sin;
        self.source_v * (1.0 + self.ripple_fraction * s)
    }

    /// A stiff bus at `v` volts.
    pub fn stiff(v: f32) -> Self {
        Self::new(v, 0.0, 0.0)
    }

    /// Bus voltage, V.
    pub fn bus_voltage(&self) -> f32 {
        self.bus_v
    }

    /// Source voltage, V.
    pub fn source_voltage(&self) -> f32 {
        self.source_v
    }

    /// Changes the source voltage, V (a mains sag); the bus follows through the link.
    pub fn set_source_voltage(&mut self, v: f32) {
        self.source_v = v;
    }

    /// Integrates one period of `ts` seconds (forward Euler) in which the inverter drew
    /// the mean current `dc_current` (A; negative when regenerating): the rectifier only
    /// conducts into the bus, so braking energy charges the capacitor.
    pub fn step(&mut self, dc_current: f32, ts: f32) {
        self.ripple_phase = wrap_angle(self.ripple_phase + self.ripple_frequency * ts);
        let source = self.source_now();
        if self.capacitance_f > 0.0 && self.source_resistance_ohm > 0.0 {
            let i_src = ((source - self.bus_v) / self.source_resistance_ohm).max(0.0);
            self.bus_v += ts * (i_src - dc_current) / self.capacitance_f;
            self.bus_v = self.bus_v.max(0.0);
        } else {
            self.bus_v = source;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stiff_link_follows_the_source() {
        let mut l = DcLink::stiff(325.0);
        l.step(10.0, 200e-6);
        assert_eq!(l.bus_voltage(), 325.0);
        l.set_source_voltage(150.0);
        l.step(0.0, 200e-6);
        assert_eq!(l.bus_voltage(), 150.0);
    }

    /// A stiff link with a 10 % 100 Hz ripple: the bus swings +/-10 % with a 10 ms period.
    #[test]
    fn ripple_rides_on_the_source() {
        let mut l = DcLink::stiff(300.0).with_ripple(0.1, 100.0);
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        for _ in 0..100 {
            l.step(0.0, 100e-6); // 10 ms: one ripple period
            lo = lo.min(l.bus_voltage());
            hi = hi.max(l.bus_voltage());
        }
        assert!(
            (hi - 330.0).abs() < 0.1 && (lo - 270.0).abs() < 0.1,
            "{lo} .. {hi}"
        );
        assert!(
            (l.bus_voltage() - 300.0).abs() < 0.5,
            "back at the zero crossing"
        );
    }

    /// Regenerated current charges the capacitor: dv = i dt / C (the rectifier blocks).
    #[test]
    fn regeneration_charges_the_capacitor() {
        let mut l = DcLink::new(325.0, 220e-6, 1.0);
        for _ in 0..100 {
            l.step(-2.0, 200e-6);
        }
        let expect = 325.0 + 2.0 * 100.0 * 200e-6 / 220e-6;
        assert!(
            (l.bus_voltage() - expect).abs() < 0.01,
            "{}",
            l.bus_voltage()
        );
    }

    /// After a sag the bus discharges into the load and never goes negative.
    #[test]
    fn a_sag_discharges_the_bus_to_the_load() {
        let mut l = DcLink::new(325.0, 470e-6, 1.0);
        l.set_source_voltage(150.0);
        for _ in 0..10_000 {
            l.step(5.0, 200e-6);
        }
        assert!(l.bus_voltage() < 150.0 && l.bus_voltage() >= 0.0);
    }
}
