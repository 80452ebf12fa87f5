//! DC link: a stiff source, or a diode rectifier charging the bus capacitor through a
//! source resistance (no braking chopper), integrated once per control period with the
//! inverter's mean DC current of that period.

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
        }
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
        if self.capacitance_f > 0.0 && self.source_resistance_ohm > 0.0 {
            let i_src = ((self.source_v - self.bus_v) / self.source_resistance_ohm).max(0.0);
            self.bus_v += ts * (i_src - dc_current) / self.capacitance_f;
            self.bus_v = self.bus_v.max(0.0);
        } else {
            self.bus_v = self.source_v;
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
